//! `fogplanes table` writes `index.html`: one self-contained page that shows the reference and
//! every estimator of the table, holds the table and the plot, and refers to nothing outside
//! itself. Its script, `src/page/viewer.js`, parses (`node --check`, when node is installed).
//! (The page's own unit tests, the JSON escaping among them, are in `src/page/mod.rs`;
//! `tests/browser/check.sh` opens the page in headless Chromium, outside `cargo test`.)

use std::io::Write as _;
use std::path::Path;
use std::process::Command;

/// Everything in `html` that could make a browser load from outside the page: any absolute URL
/// (`scheme://`), a `src`, `href`, `srcset`, `poster`, `action`, `formaction` or `background`
/// attribute or CSS `url(...)` whose value is not `data:` or `#...`, `@import`, elements that
/// embed other documents, and the script calls that reach the network.
fn outside_references(html: &str) -> Vec<String> {
    let lower = html.to_ascii_lowercase();
    let mut found = Vec::new();
    let around = |i: usize| lower[i.saturating_sub(20)..(i + 60).min(lower.len())].replace('\n', " ");
    let local = |value: &str| {
        let v = value.trim_start().trim_start_matches(['"', '\'']).trim_start();
        v.starts_with("data:") || v.starts_with('#')
    };
    for (i, _) in lower.match_indices("://") {
        found.push(around(i));
    }
    for name in ["src", "href", "srcset", "poster", "action", "formaction", "background"] {
        for (i, _) in lower.match_indices(name) {
            let before = lower[..i].chars().next_back();
            if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
                continue; // part of a longer name: "default-src", "srcCanvas"
            }
            let rest = lower[i + name.len()..].trim_start();
            if let Some(value) = rest.strip_prefix('=').filter(|v| !v.starts_with('='))
                && !local(value)
            {
                found.push(around(i));
            }
        }
    }
    for (i, _) in lower.match_indices("url(") {
        if !local(&lower[i + 4..]) {
            found.push(around(i));
        }
    }
    for pattern in [
        "@import",
        "<link",
        "<iframe",
        "<object",
        "<embed",
        "<base",
        "fetch(",
        "xmlhttprequest",
        "websocket",
        "eventsource",
        "sendbeacon",
        "importscripts",
        "new worker",
    ] {
        for (i, _) in lower.match_indices(pattern) {
            found.push(around(i));
        }
    }
    found
}

#[test]
fn the_checker_finds_outside_references() {
    for bad in [
        "<img src=\"a.png\">",
        "<script src='//cdn.test/x.js'></script>",
        "<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>",
        "<a href = \"page.html\">",
        "<div style=\"background: url(a.png)\">",
        "<style>@import 'a.css';</style>",
        "<script>fetch(u)</script>",
        "<script>x.src = name</script>",
        "<link rel=stylesheet href=a.css>",
    ] {
        assert!(!outside_references(bad).is_empty(), "missed {bad}");
    }
    for good in [
        "<meta content=\"default-src 'none'; img-src data: blob:\">",
        "<a href=\"#results\">",
        "<script>if (a.src === b) {} const srcCanvas = 1;</script>",
        "<div style=\"background:url('data:image/png;base64,AA')\">",
        "<img src=\"data:image/svg+xml;base64,PHN2Zy8+\" alt=\"plot\">",
    ] {
        assert_eq!(outside_references(good), Vec::<String>::new(), "flagged {good}");
    }
}

#[test]
fn table_writes_a_self_contained_comparison_page() {
    let dir = std::env::temp_dir().join(format!("fogplanes-page-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let reference = dir.join("ref.exr");
    let out = dir.join("report");
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_fogplanes")).args(args).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    };
    let scene = "media_scenes/six_lights.toml";
    let r = reference.to_str().unwrap();
    run(&["reference", scene, "--resolution", "32x18", "--spp", "16", "--quiet", "-o", r]);
    run(&[
        "table",
        scene,
        "--resolution",
        "32x18",
        "--reference",
        r,
        "--planes",
        "500",
        "--sweep",
        "250,500",
        "--sweep-seeds",
        "1",
        "--orientations",
        "3",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    let html = std::fs::read_to_string(out.join("index.html")).expect("index.html is written");
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));

    // The reference and every estimator of the table: a button, a table row, an image.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap()).unwrap();
    // The page shows the default (Sobol) sampler's images; the table has both samplers' rows.
    let rows: Vec<&str> = json["rows"].as_array().unwrap().iter().map(|r| r["estimator"].as_str().unwrap()).collect();
    assert_eq!(rows.len(), 14, "{rows:?}");
    for label in &rows {
        assert!(html.contains(&format!("<th scope=\"row\">{label}</th>")), "no table row for {label}");
    }
    let labels: Vec<&str> = rows.into_iter().filter(|l| !l.ends_with("/independent")).collect();
    assert_eq!(labels.len(), 7, "{labels:?}");
    assert!(html.contains("<kbd>1</kbd><span>reference</span>"));
    assert!(html.contains("{\"label\":\"reference\",\"png\":\""));
    for (k, label) in labels.iter().enumerate() {
        assert!(html.contains(&format!("<kbd>{}</kbd><span>{label}</span>", k + 2)), "no button for {label}");
        assert!(html.contains(&format!("<th scope=\"row\">{label}</th>")), "no table row for {label}");
        assert!(html.contains(&format!("{{\"label\":\"{label}\",\"png\":\"")), "no image of {label}");
    }
    assert_eq!(html.matches("\"png\":\"").count(), 1 + labels.len());
    // The table's columns, the inlined plot and the notes.
    for column in ["SMAPE x10^2", "MSE x10^4", "ns/hit", "gather time vs unweighted"] {
        assert!(html.contains(&format!("<th scope=\"col\">{column}</th>")), "no column {column}");
    }
    // The plot: error_vs_time.svg as an image, base64 of the same length, an `<svg` document.
    let svg = std::fs::read(out.join("error_vs_time.svg")).unwrap();
    let plot = html.split("<img src=\"data:image/svg+xml;base64,").nth(1).expect("no plot");
    let plot = &plot[..plot.find('"').unwrap()];
    assert_eq!(plot.len(), svg.len().div_ceil(3) * 4);
    assert!(svg.starts_with(b"<svg") && plot.starts_with("PHN2Zy"), "{}", &plot[..20]);
    assert!(html.contains("six_lights at 32x18, ") && html.contains(", 500 photon planes") && html.contains("ref.exr"));

    // The structure: sections in order, the data block as JSON, nothing left unfilled.
    let data = page_structure(&html);
    assert_eq!((data["width"].as_u64(), data["height"].as_u64()), (Some(32), Some(18)));
    let shown: Vec<&str> = data["images"].as_array().unwrap().iter().map(|i| i["label"].as_str().unwrap()).collect();
    assert_eq!(shown, std::iter::once("reference").chain(labels.iter().copied()).collect::<Vec<_>>());
    for image in data["images"].as_array().unwrap() {
        assert!(image["png"].as_str().unwrap().starts_with("iVBORw0KGgo"), "not a base64 PNG");
    }

    // Nothing from outside, and a policy that forbids it anyway.
    assert_eq!(outside_references(&html), Vec::<String>::new());
    assert!(html.contains("Content-Security-Policy\" content=\"default-src 'none';"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Checks the page's structure and returns its data block, parsed: one `<style>`, exactly two
/// scripts (the JSON data, then the viewer), the header, viewer, results (and plot, when there
/// is one) in this order before them, unique ids, no `{{slot}}` of the template left.
fn page_structure(html: &str) -> serde_json::Value {
    assert!(html.starts_with("<!DOCTYPE html>\n<html lang=\"en\">") && html.ends_with("</body>\n</html>\n"));
    let lower = html.to_ascii_lowercase();
    for (tag, n) in [("<script", 2), ("</script", 2), ("<style", 1), ("</style", 1), ("<header", 1), ("<main", 1)] {
        assert_eq!(lower.matches(tag).count(), n, "{tag}");
    }
    assert!(!html.contains("{{"), "a slot of the template is left");
    let mut at = 0;
    for marker in ["<header>", "<section id=\"viewer\"", "<section id=\"results\"", "</main>"] {
        at += html[at..].find(marker).unwrap_or_else(|| panic!("{marker} missing or out of order"));
    }
    if let Some(plot) = html.find("<section id=\"plot\"") {
        assert!(html.find("<section id=\"results\"").unwrap() < plot && plot < at, "the plot follows the results");
    }
    let open = "</main>\n<script type=\"application/json\" id=\"fog-data\">";
    let start = html.find(open).expect("the data block right after </main>") + open.len();
    let end = start + lower[start..].find("</script").unwrap();
    assert!(html[end..].starts_with("</script>\n<script>\n\"use strict\";"), "the viewer follows the data");
    let mut ids: Vec<&str> = html[..start].split(" id=\"").skip(1).map(|s| &s[..s.find('"').unwrap()]).collect();
    let count = ids.len();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), count, "duplicate ids");
    serde_json::from_str(&html[start..end]).expect("the data block is JSON")
}

/// `node --check` on the page's script: it parses. Needs node; without it, SKIPPED.
#[test]
fn the_viewer_script_parses() {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/src/page/viewer.js");
    match Command::new("node").arg("--check").arg(script).output() {
        Err(e) => {
            // Straight to standard error, past the test harness's capture: a skip is seen.
            let _ = writeln!(
                std::io::stderr().lock(),
                "\n{bar}\nSKIPPED: node is not installed ({e}; apt-get install nodejs)\n         \
                 the_viewer_script_parses checked nothing: no `node --check` of viewer.js\n{bar}",
                bar = "=".repeat(82)
            );
        }
        Ok(o) => assert!(o.status.success(), "node --check {script}:\n{}", String::from_utf8_lossy(&o.stderr)),
    }
}

/// The page of a 16x9 table without a sweep (200 planes) against a 4-spp reference written to
/// `reference`; the table goes to `out`.
fn small_page(scene: &Path, reference: &Path, out: &Path) -> String {
    let (s, r) = (scene.to_str().unwrap(), reference.to_str().unwrap());
    for args in [
        vec!["reference", s, "--resolution", "16x9", "--spp", "4", "--quiet", "-o", r],
        vec!["table", s, "--resolution", "16x9", "--reference", r, "--planes", "200", "--no-sweep", "--quiet"],
    ] {
        let mut c = Command::new(env!("CARGO_BIN_EXE_fogplanes"));
        c.args(&args);
        if args[0] == "table" {
            c.arg("--out").arg(out);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    std::fs::read_to_string(out.join("index.html")).unwrap()
}

/// A scene file and a reference path full of HTML's special characters make an ordinary page:
/// the title and notes are text, not markup.
#[test]
fn names_with_markup_are_text_on_the_page() {
    let dir = std::env::temp_dir().join(format!("fogplanes-page-names-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("a<")).unwrap();
    let scene = dir.join("<!--<script>&'x.toml");
    std::fs::copy("media_scenes/six_lights.toml", &scene).unwrap();
    let reference = dir.join("a<").join("script>\"b.exr"); // the path holds `</script>"`
    let html = small_page(&scene, &reference, &dir.join("report"));
    page_structure(&html);
    assert!(html.contains("<title>fogplanes: &lt;!--&lt;script&gt;&amp;&#39;x estimators</title>"));
    assert!(html.contains("a&lt;/script&gt;&quot;b.exr"));
    assert_eq!(outside_references(&html), Vec::<String>::new());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_page_has_no_plot_without_a_sweep() {
    let dir = std::env::temp_dir().join(format!("fogplanes-page-nosweep-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("report");
    let html = small_page(Path::new("media_scenes/six_lights.toml"), &dir.join("ref.exr"), &out);
    page_structure(&html);
    assert!(
        !html.contains("id=\"plot\"") && !html.contains("data:image/svg") && !out.join("error_vs_time.svg").exists()
    );
    assert!(html.contains("<th scope=\"row\">unweighted</th>"));
    assert_eq!(outside_references(&html), Vec::<String>::new());
    std::fs::remove_dir_all(&dir).unwrap();
}
