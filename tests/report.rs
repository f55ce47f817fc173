//! `report.html` in a real headless browser (Debian's Chromium, installed by
//! `.ci/run`): the page a run leaves loads with no error and no network,
//! every figure decodes, the animation plays, and it says what the summary
//! says.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::Command;

use shoal_tests::*;

/// The page's DOM after `budget_ms` of virtual time in headless Chromium.
fn rendered_dom(page: &Path, budget_ms: u32) -> String {
    let chromium = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|c| {
            Command::new(c)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .expect("a headless Chromium is required (.ci/run installs Debian's `chromium`)");
    let o = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            // no network at all: a page that needs it fails to show
            "--proxy-server=127.0.0.1:9",
            "--proxy-bypass-list=<-loopback>",
            &format!("--virtual-time-budget={budget_ms}"),
            "--dump-dom",
        ])
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "chromium: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// The value of `attr` on the `<body>` tag.
fn body_attr(dom: &str, attr: &str) -> Option<String> {
    let start = dom.find("<body")?;
    let tag = &dom[start..start + dom[start..].find('>')?];
    let key = format!("{attr}=\"");
    let i = tag.find(&key)? + key.len();
    Some(tag[i..i + tag[i..].find('"')?].to_string())
}

#[test]
fn every_run_leaves_a_report_that_a_browser_shows_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let out = run_small(tmp.path(), "report", 20.0);
    let page = out.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    // Self-contained: nothing to fetch.
    for outside in ["http://", "https://", "src=\"/", "href=\"/", "@import"] {
        assert!(!html.contains(outside), "the page refers to {outside}");
    }
    let dom = rendered_dom(&page, 4000);
    assert_eq!(
        body_attr(&dom, "data-ready").as_deref(),
        Some("1"),
        "{dom:.2000}"
    );
    let errors_at = dom.find("<pre id=\"errors\">").unwrap();
    let errors = &dom[errors_at + 17..errors_at + dom[errors_at..].find("</pre>").unwrap()];
    assert!(errors.trim().is_empty(), "the page reports: {errors}");
    let figures = html.matches("<figure>").count();
    assert!(figures >= 6, "{figures} figures");
    // It says how to open the run in Foxglove and Rerun, linking the files
    // beside it: the recording, and the export the command it names writes.
    assert!(html.contains("href=\"recording.mcap\"") && out.join("recording.mcap").is_file());
    assert!(html.contains("href=\"foxglove.mcap\"") && html.contains("rerun foxglove.mcap"));
    let o = run_shoal_ok(&[
        "export",
        out.join("recording.mcap").to_str().unwrap(),
        "--foxglove",
        out.join("foxglove.mcap").to_str().unwrap(),
    ]);
    assert!(o.status.success() && out.join("foxglove.mcap").is_file());
    assert_eq!(
        body_attr(&dom, "data-images").and_then(|n| n.parse::<usize>().ok()),
        Some(figures),
        "every figure decodes"
    );
    let frames: u32 = body_attr(&dom, "data-frames").unwrap().parse().unwrap();
    assert!(frames >= 2, "the animation drew {frames} frame(s)");
    // It says what the summary says.
    let s = summary(&out);
    let word = if s["verdict"]["pass"].as_bool().unwrap() {
        "PASS"
    } else {
        "FAIL"
    };
    assert!(dom.contains(&format!("id=\"verdict\">{word}<")), "verdict");
    let min_pair = format!(
        "{:.2} m ({})",
        s["safety"]["min_pair_distance_m"].as_f64().unwrap(),
        s["safety"]["min_pair"].as_str().unwrap()
    );
    assert!(dom.contains(&min_pair), "{min_pair} not in the page");

    // `shoal summarize` writes the same page from the recording alone.
    let again = tmp.path().join("again");
    run_shoal_ok(&[
        "summarize",
        "--quiet",
        out.join("recording.mcap").to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
    ]);
    let dom = rendered_dom(&again.join("report.html"), 2000);
    assert_eq!(body_attr(&dom, "data-ready").as_deref(), Some("1"));
    assert!(dom.contains(&min_pair));
}
