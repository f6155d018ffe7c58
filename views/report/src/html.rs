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
    let body = collapse_appendix(&body);
    let title = title
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;");
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>{title}</title>\n<style>\n{STYLE}</style>\n</head>\n<body>\n{body}</body>\n</html>\n"
    )
}

/// The heading after which every section is collapsed in the HTML.
const APPENDIX: &str = "<h2>Appendix</h2>";

/// Every `<h2>` section after the appendix heading as a collapsed
/// `<details>` block titled by its heading: the first screen stays open,
/// the rest a click away.
fn collapse_appendix(body: &str) -> String {
    let Some(at) = body.find(APPENDIX) else {
        return body.to_string();
    };
    let (first, rest) = body.split_at(at + APPENDIX.len());
    let mut out = first.to_string();
    let mut sections = rest.split("<h2>");
    out.push_str(sections.next().unwrap_or(""));
    for section in sections {
        let (heading, content) = section.split_once("</h2>").unwrap_or((section, ""));
        out.push_str(&format!(
            "<details>\n<summary>{heading}</summary>\n{content}</details>\n"
        ));
    }
    out
}

const STYLE: &str = "body { font-family: sans-serif; max-width: 70em; margin: 2em auto; padding: 0 1em; line-height: 1.45; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.2em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; }
th { background: #f3f3f3; }
td[style*=\"right\"], th[style*=\"right\"] { font-variant-numeric: tabular-nums; }
img { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
code { background: #f5f5f5; padding: 0 0.2em; }
details { margin: 0.4em 0; }
summary { font-size: 1.3em; font-weight: bold; cursor: pointer; padding: 0.3em 0; }
";

#[cfg(test)]
mod tests {
    #[test]
    fn sections_after_the_appendix_collapse() {
        let page = super::page(
            "t",
            "# t\n\nfirst\n\n## Appendix\n\nbelow\n\n## A\n\na\n\n## B\n\nb\n",
        );
        assert!(page.contains("<p>first</p>"));
        assert!(page.contains("<h2>Appendix</h2>\n<p>below</p>"), "{page}");
        assert!(
            page.contains("<details>\n<summary>A</summary>\n\n<p>a</p>\n</details>"),
            "{page}"
        );
        assert!(page.contains("<summary>B</summary>"), "{page}");
        assert_eq!(page.matches("<details>").count(), 2);
    }

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
