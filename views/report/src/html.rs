//! The report as HTML beside the Markdown: the same text, its tables and
//! its charts (the SVG files beside it, by relative path), readable in any
//! browser without a Markdown viewer.

use pulldown_cmark::{Options, Parser, html};

/// File name of the HTML report.
pub const HTML_FILE: &str = "report.html";

/// `markdown` as a standalone HTML page titled `title`.
pub fn page(title: &str, markdown: &str) -> String {
    let mut body = String::new();
    html::push_html(
        &mut body,
        Parser::new_ext(
            markdown,
            Options::ENABLE_TABLES | Options::ENABLE_STRIKETHROUGH,
        ),
    );
    let title = title
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;");
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>{title}</title>\n<style>\n{STYLE}</style>\n</head>\n<body>\n{body}</body>\n</html>\n"
    )
}

const STYLE: &str = "body { font-family: sans-serif; max-width: 70em; margin: 2em auto; padding: 0 1em; line-height: 1.45; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.2em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; }
th { background: #f3f3f3; }
td[style*=\"right\"], th[style*=\"right\"] { font-variant-numeric: tabular-nums; }
img { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
code { background: #f5f5f5; padding: 0 0.2em; }
";

#[cfg(test)]
mod tests {
    #[test]
    fn tables_and_images_become_html() {
        let page = super::page(
            "a <b>",
            "# t\n\n![c](c.svg)\n\n| a | b |\n|---|---:|\n| 1 | 2 |\n",
        );
        assert!(page.contains("<title>a &lt;b&gt;</title>"));
        assert!(page.contains("<img src=\"c.svg\" alt=\"c\" />"), "{page}");
        assert!(
            page.contains("<td style=\"text-align: right\">2</td>"),
            "{page}"
        );
    }
}
