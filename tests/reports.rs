//! What readers of the committed reports see: every chart keeps its text
//! inside the canvas with no two labels overlapping, and every report's
//! HTML, opened in a real browser (headless Chromium), loads every chart.

use std::process::Command;

use crate::common::committed_reports;

/// A text element's box on the canvas (px), estimated from its font size:
/// sans-serif glyphs are at most about 0.6 em wide on average.
#[derive(Debug)]
struct Label {
    text: String,
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

/// The canvas size and every text element's box.
fn labels(svg: &str) -> ((f64, f64), Vec<Label>) {
    let doc = roxmltree::Document::parse(svg).unwrap();
    let root = doc.root_element();
    let number = |n: roxmltree::Node, attr: &str| -> f64 {
        n.attribute(attr)
            .unwrap_or("0")
            .parse()
            .unwrap_or_else(|_| panic!("{attr} of {n:?}"))
    };
    let size = (number(root, "width"), number(root, "height"));
    let mut out = Vec::new();
    for n in doc.descendants().filter(|n| n.has_tag_name("text")) {
        let text = n.text().unwrap_or("").trim().to_string();
        if text.is_empty() {
            continue;
        }
        let (x, y, em) = (number(n, "x"), number(n, "y"), number(n, "font-size"));
        let w = text.chars().count() as f64 * 0.6 * em;
        // Offsets from the anchor, before any rotation about it.
        let (dx0, dx1) = match n.attribute("text-anchor") {
            Some("middle") => (-w / 2.0, w / 2.0),
            Some("end") => (-w, 0.0),
            _ => (0.0, w),
        };
        let (dy0, dy1) = match n.attribute("dy") {
            Some("0.76em") => (0.0, em),
            Some("-0.5ex") => (-em, 0.0),
            _ => (-em / 2.0, em / 2.0),
        };
        let corners = [(dx0, dy0), (dx1, dy0), (dx0, dy1), (dx1, dy1)];
        let rotate = n.attribute("transform").map(|t| {
            t.trim_start_matches("rotate(")
                .split([',', ')'])
                .next()
                .unwrap()
                .trim()
                .parse::<f64>()
                .unwrap()
        });
        let turned: Vec<(f64, f64)> = corners
            .iter()
            .map(|&(dx, dy)| match rotate {
                Some(deg) => {
                    let (s, c) = deg.to_radians().sin_cos();
                    (dx * c - dy * s, dx * s + dy * c)
                }
                None => (dx, dy),
            })
            .collect();
        let xs = turned.iter().map(|p| x + p.0);
        let ys = turned.iter().map(|p| y + p.1);
        out.push(Label {
            text,
            x0: xs.clone().fold(f64::MAX, f64::min),
            x1: xs.fold(f64::MIN, f64::max),
            y0: ys.clone().fold(f64::MAX, f64::min),
            y1: ys.fold(f64::MIN, f64::max),
        });
    }
    (size, out)
}

/// Problems with a chart's text: labels outside the canvas, labels over
/// each other (boxes overlapping by more than a pixel each way).
fn text_problems(svg: &str) -> Vec<String> {
    let ((w, h), labels) = labels(svg);
    let mut problems = Vec::new();
    for l in &labels {
        if l.x0 < -0.5 || l.y0 < -0.5 || l.x1 > w + 0.5 || l.y1 > h + 0.5 {
            problems.push(format!("`{}` leaves the {w}×{h} canvas: {l:?}", l.text));
        }
    }
    for (i, a) in labels.iter().enumerate() {
        for b in &labels[..i] {
            let x = a.x1.min(b.x1) - a.x0.max(b.x0);
            let y = a.y1.min(b.y1) - a.y0.max(b.y0);
            if x > 1.0 && y > 1.0 {
                problems.push(format!("`{}` overlaps `{}`", a.text, b.text));
            }
        }
    }
    problems
}

#[test]
fn the_geometry_check_finds_what_it_should() {
    let svg = |texts: &str| {
        format!(
            "<svg width=\"200\" height=\"100\" xmlns=\"http://www.w3.org/2000/svg\">{texts}</svg>"
        )
    };
    let text = |x: u32, y: u32, s: &str| {
        format!(
            "<text x=\"{x}\" y=\"{y}\" dy=\"0.5ex\" text-anchor=\"start\" font-size=\"10\">{s}</text>"
        )
    };
    assert!(text_problems(&svg(&(text(10, 20, "one") + &text(10, 50, "two")))).is_empty());
    let over = text_problems(&svg(&(text(10, 20, "one") + &text(20, 22, "two"))));
    assert_eq!(over, ["`two` overlaps `one`"]);
    let out = text_problems(&svg(&text(180, 20, "far too long")));
    assert!(out[0].contains("leaves the 200×100 canvas"), "{out:?}");
    // A y-axis title, turned to read upwards, stands as tall as it is long.
    let turned = "<text x=\"10\" y=\"50\" dy=\"0.5ex\" text-anchor=\"middle\" font-size=\"10\" \
                  transform=\"rotate(270, 10, 50)\">0123456789</text>";
    let ((_, _), l) = labels(&svg(turned));
    assert!((l[0].y1 - l[0].y0 - 60.0).abs() < 1e-9 && (l[0].x1 - l[0].x0 - 10.0).abs() < 1e-9);
}

#[test]
fn every_committed_chart_keeps_its_text_apart_and_on_the_canvas() {
    let mut checked = 0;
    let mut problems = Vec::new();
    for dir in committed_reports() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "svg") {
                let svg = std::fs::read_to_string(&path).unwrap();
                problems.extend(
                    text_problems(&svg)
                        .into_iter()
                        .map(|p| format!("{}: {p}", path.display())),
                );
                checked += 1;
            }
        }
    }
    assert!(checked >= 20, "{checked} charts");
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The charts a report's Markdown shows.
fn charts_of(markdown: &str) -> Vec<String> {
    markdown
        .split("](")
        .skip(1)
        .filter_map(|rest| rest.find(')').map(|end| rest[..end].to_string()))
        .filter(|target| target.ends_with(".svg"))
        .collect()
}

#[test]
#[ignore = "full suite: needs a headless Chromium"]
fn every_committed_report_opens_in_a_browser_with_every_chart() {
    let browser = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| {
            Command::new(b)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .expect(
            "a headless browser: install Debian's chromium (`apt-get install chromium`, or `cargo \
             xtask test`, which installs what the suite needs)",
        );
    for dir in committed_reports() {
        let markdown = std::fs::read_to_string(dir.join("report.md")).unwrap();
        let charts = charts_of(&markdown);
        assert!(!charts.is_empty(), "{}", dir.display());
        let html = std::fs::read_to_string(dir.join("report.html"))
            .unwrap_or_else(|e| panic!("{}: report.html: {e}", dir.display()));
        // Open a copy with a script that reports, once the page has
        // loaded, which images the browser could not draw.
        let work = tempfile::tempdir().unwrap();
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, work.path().join(path.file_name().unwrap())).unwrap();
        }
        let probe = "<script>window.addEventListener('load', () => { const images = \
                     [...document.images]; const broken = images.filter(i => !(i.complete && \
                     i.naturalWidth > 0)).map(i => i.getAttribute('src')); \
                     document.body.setAttribute('data-charts', images.length + ' loaded, ' + \
                     broken.length + ' broken: ' + broken.join(' ')); });</script></body>";
        let page = work.path().join("probe.html");
        std::fs::write(&page, html.replace("</body>", probe)).unwrap();
        let shot = work.path().join("shot.png");
        let url = format!("file://{}", page.display());
        let open = |action: &str| {
            Command::new(browser)
                .args([
                    "--headless",
                    "--no-sandbox",
                    "--disable-gpu",
                    "--hide-scrollbars",
                    "--allow-file-access-from-files",
                    "--virtual-time-budget=10000",
                    "--window-size=1280,4000",
                    action,
                    &url,
                ])
                .output()
                .unwrap()
        };
        let out = open("--dump-dom");
        let dom = String::from_utf8_lossy(&out.stdout);
        let expected = format!("data-charts=\"{} loaded, 0 broken: \"", charts.len());
        assert!(
            dom.contains(&expected),
            "{}: expected {expected}; the browser said {:?}\n{}",
            dir.display(),
            dom.split("data-charts=")
                .nth(1)
                .map(|s| &s[..s.len().min(200)]),
            String::from_utf8_lossy(&out.stderr)
        );
        // The same page as pixels: a screenshot, and not a blank one.
        open(&format!("--screenshot={}", shot.display()));
        let png = std::fs::read(&shot).unwrap_or_default();
        assert!(
            png.len() > 20_000,
            "{}: screenshot of {} bytes",
            dir.display(),
            png.len()
        );
    }
}
