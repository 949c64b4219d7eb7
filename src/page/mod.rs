//! `index.html`: a self-contained, offline, interactive comparison page for the `table` command.
//!
//! The page shows one image at a time in a large view (the reference or one estimator), flips
//! between them with buttons and the number keys, zooms with pixel-exact magnification, pans,
//! changes exposure, and shows beside it the chosen estimator's false-colour per-pixel error
//! against the reference, with the same zoom and pan. Under the cursor it reads out the pixel
//! values. The table and the error-versus-time plot follow below.
//!
//! Everything is in the one HTML string, assembled here from three files beside this one:
//! `viewer.html`, the page's skeleton with `{{name}}` slots ([`fill`]), `viewer.css` and
//! `viewer.js` (its style and script, inlined; `tests/page.rs` runs `node --check` on the
//! script). The images travel as base64 PNGs ([`rgbe`]) in a JSON block written by serde_json
//! ([`script_json`]); the plot is the caller's SVG document, unchanged, as an `<img>` with a
//! `data:` URI. Nothing is fetched: the page holds no `http://` or `https://` text at all (the
//! plot's namespace names travel inside its base64), and a Content-Security-Policy forbids
//! every network load.

mod rgbe;

use std::fmt;
use std::fmt::Write as _;

/// One image for the page: linear RGB, row-major, top row first.
#[derive(Clone, Copy, Debug)]
pub struct PageImage<'a> {
    pub label: &'a str,
    pub width: u32,
    pub height: u32,
    pub pixels: &'a [[f32; 3]],
}

/// Everything the page shows.
#[derive(Clone, Debug)]
pub struct PageInput<'a> {
    pub title: &'a str,
    pub reference: PageImage<'a>,
    /// The estimators, in table order.
    pub images: Vec<PageImage<'a>>,
    /// An HTML `<table>` (see [`html_table`]), inserted as it is.
    pub table_html: &'a str,
    /// The error-versus-time plot: an SVG document, shown as it is as an image (`<img>` with a
    /// `data:` URI). An image is a document of its own: it keeps its XML prolog and namespaces,
    /// stays vector (crisp at any zoom), runs no script, loads nothing and cannot restyle the
    /// page.
    pub plot_svg: Option<&'a str>,
    /// A paragraph of plain text (escaped here; line breaks are kept).
    pub notes: &'a str,
}

/// Why no page could be made.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PageError {
    /// An image with zero width or height.
    Empty { label: String },
    /// An image too large for the page (more than [`MAX_SIDE`] pixels on a side).
    TooLarge { label: String, width: u32, height: u32 },
    /// An image whose pixel slice does not hold width x height pixels.
    PixelCount { label: String, width: u32, height: u32, pixels: usize },
    /// An image whose size differs from the reference's.
    SizeMismatch { label: String, size: (u32, u32), reference: (u32, u32) },
    /// The caller's title, notes, labels or table refer to something outside the page (see
    /// [`network_references`]).
    ExternalReference(Vec<String>),
    /// The PNG encoder failed.
    Encode(String),
    /// The image data could not be written as JSON.
    Json(String),
}

impl fmt::Display for PageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PageError::Empty { label } => write!(f, "image {label:?} is empty"),
            PageError::TooLarge { label, width, height } => {
                write!(f, "image {label:?} is {width}x{height}, more than {MAX_SIDE} on a side")
            }
            PageError::PixelCount { label, width, height, pixels } => {
                write!(f, "image {label:?} is {width}x{height} but holds {pixels} pixels")
            }
            PageError::SizeMismatch { label, size, reference } => {
                write!(f, "image {label:?} is {}x{}, the reference {}x{}", size.0, size.1, reference.0, reference.1)
            }
            PageError::ExternalReference(refs) => {
                write!(f, "the page would load from outside itself: {}", refs.join(", "))
            }
            PageError::Encode(e) => write!(f, "PNG encoding failed: {e}"),
            PageError::Json(e) => write!(f, "the page's image data could not be written as JSON: {e}"),
        }
    }
}

impl std::error::Error for PageError {}

/// The largest width or height the page takes: the encoded PNG is twice as wide and high, and
/// browsers cap canvases at 16384 (some) to 32767 pixels a side.
pub const MAX_SIDE: u32 = 8192;

/// The page's skeleton: `{{title}}`, `{{css}}`, `{{notes}}`, `{{buttons}}`, `{{table}}`,
/// `{{plot}}`, `{{data}}` and `{{js}}` mark where [`comparison_page`] puts each part.
const TEMPLATE: &str = include_str!("viewer.html");
/// The page's style (dark theme, the two views, the table and the plot).
const CSS: &str = include_str!("viewer.css");
/// The viewer: decodes the images, draws both views, handles keys, pointer and controls.
const JS: &str = include_str!("viewer.js");

/// The page: one HTML string.
pub fn comparison_page(input: &PageInput) -> Result<String, PageError> {
    let size = (input.reference.width, input.reference.height);
    let all: Vec<&PageImage> = std::iter::once(&input.reference).chain(&input.images).collect();
    for image in &all {
        check_image(image, size)?;
    }

    let title = escape_html(input.title);
    let notes = match input.notes.trim() {
        "" => String::new(),
        text => format!("<p class=\"notes\">{}</p>\n", escape_html(text)),
    };
    let buttons = buttons_html(&all);
    // Belt and braces (the Content-Security-Policy forbids every load anyway): the caller's parts
    // are checked for outside references before the (large, base64-only) payload is made. The
    // plot needs no check: an SVG shown as an image loads nothing.
    let refs: Vec<String> =
        [title.as_str(), &notes, &buttons, input.table_html].into_iter().flat_map(network_references).collect();
    if !refs.is_empty() {
        return Err(PageError::ExternalReference(refs));
    }

    let plot = input.plot_svg.map_or(String::new(), |svg| {
        format!(
            "<section id=\"plot\">\n<h2>Error versus time</h2>\n<figure class=\"plot\">\n\
             <img src=\"data:image/svg+xml;base64,{}\" alt=\"Error against time, one line per estimator\">\n\
             </figure>\n</section>\n",
            base64(svg.as_bytes())
        )
    });
    let data = PageData {
        width: size.0,
        height: size.1,
        images: all
            .iter()
            .map(|image| {
                let png = rgbe::encode_png(image.width, image.height, image.pixels)
                    .map_err(|e| PageError::Encode(e.to_string()))?;
                Ok(EncodedImage { label: image.label, png: base64(&png) })
            })
            .collect::<Result<_, PageError>>()?,
    };
    let data = script_json(&data).map_err(|e| PageError::Json(e.to_string()))?;
    Ok(fill(
        TEMPLATE,
        &[
            ("title", &title),
            ("css", CSS),
            ("notes", &notes),
            ("buttons", &buttons),
            ("table", input.table_html),
            ("plot", &plot),
            ("data", &data),
            ("js", JS),
        ],
    ))
}

/// The JSON block the script reads: `{"width":W,"height":H,"images":[{"label":..,"png":..}]}`,
/// `images[0]` the reference, `png` base64 (see [`rgbe`]).
#[derive(serde::Serialize)]
struct PageData<'a> {
    width: u32,
    height: u32,
    images: Vec<EncodedImage<'a>>,
}

#[derive(serde::Serialize)]
struct EncodedImage<'a> {
    label: &'a str,
    png: String,
}

/// `value` as JSON that is also safe as the text of a `<script>` element: serde_json writes it,
/// then `<`, `>` and `&` (so that no `</script>` or `<!--` can occur) and U+2028 / U+2029 become
/// `\u` escapes. JSON has these characters only inside strings, where the escape means the same.
fn script_json(value: &impl serde::Serialize) -> Result<String, serde_json::Error> {
    let json = serde_json::to_string(value)?;
    let mut out = String::with_capacity(json.len());
    for c in json.chars() {
        match c {
            '<' | '>' | '&' | '\u{2028}' | '\u{2029}' => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    Ok(out)
}

/// `template` with each `{{name}}` replaced by its part, in one pass: a part's own text is never
/// searched for slots. Panics on a slot without a part (the template is ours, and the tests
/// fill it).
fn fill(template: &str, parts: &[(&str, &str)]) -> String {
    let mut out = String::with_capacity(template.len() + parts.iter().map(|(_, p)| p.len()).sum::<usize>());
    let mut rest = template;
    while let Some(start) = rest.find("{{") {
        let end = start + rest[start..].find("}}").expect("viewer.html: a {{ without }}");
        let name = &rest[start + 2..end];
        let part = parts.iter().find(|(n, _)| *n == name).unwrap_or_else(|| panic!("viewer.html: no part {name}"));
        out.push_str(&rest[..start]);
        out.push_str(part.1);
        rest = &rest[end + 2..];
    }
    out.push_str(rest);
    out
}

/// A table for [`PageInput::table_html`]: column headers, then one row per estimator with its
/// row header (the estimator's label, so that clicking the row shows it) and its cells. All
/// text is escaped.
pub fn html_table(columns: &[&str], rows: &[(&str, Vec<String>)]) -> String {
    let mut s = String::from("<table>\n<thead><tr>");
    for c in columns {
        s.push_str(&format!("<th scope=\"col\">{}</th>", escape_html(c)));
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for (header, cells) in rows {
        s.push_str(&format!("<tr><th scope=\"row\">{}</th>", escape_html(header)));
        for c in cells {
            s.push_str(&format!("<td>{}</td>", escape_html(c)));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table>");
    s
}

fn check_image(image: &PageImage, reference: (u32, u32)) -> Result<(), PageError> {
    let label = image.label.to_string();
    let (width, height) = (image.width, image.height);
    if width == 0 || height == 0 {
        return Err(PageError::Empty { label });
    }
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(PageError::TooLarge { label, width, height });
    }
    if image.pixels.len() != width as usize * height as usize {
        return Err(PageError::PixelCount { label, width, height, pixels: image.pixels.len() });
    }
    if (width, height) != reference {
        return Err(PageError::SizeMismatch { label, size: (width, height), reference });
    }
    Ok(())
}

/// One button per image, with its number key (1-9, then 0) and label.
fn buttons_html(all: &[&PageImage]) -> String {
    let mut s = String::new();
    for (i, image) in all.iter().enumerate() {
        let key = match i {
            0..=8 => format!("<kbd>{}</kbd>", i + 1),
            9 => "<kbd>0</kbd>".to_string(),
            _ => String::new(),
        };
        let class = if i == 0 { " class=\"reference\"" } else { "" };
        s.push_str(&format!(
            "<button type=\"button\" data-index=\"{i}\"{class} aria-pressed=\"{}\">{key}<span>{}</span></button>\n",
            i == 0,
            escape_html(image.label)
        ));
    }
    s
}

// ---------------------------------------------------------------------------------------------
// Text

/// Text escaped for HTML element content and quoted attribute values.
pub fn escape_html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Standard base64 (RFC 4648, with padding), as `atob` and `data:` URIs read it.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let n =
            (chunk[0] as u32) << 16 | (*chunk.get(1).unwrap_or(&0) as u32) << 8 | *chunk.get(2).unwrap_or(&0) as u32;
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Everything in `html` that would make a browser reach outside the page: `src=`, `href=`
/// (also `xlink:href=`), `srcset=`, `poster=`, `action=`, `formaction=`, `background=` and CSS
/// `url(...)` whose value is not `data:` or `#...`; any `@import`; `fetch(` of anything but a
/// `data:` literal; `XMLHttpRequest`, `WebSocket`, `EventSource`, `sendBeacon`,
/// `importScripts`, `new Worker(`; and any absolute `http://`, `https://`, `ws://`, `wss://` or
/// `ftp://` URL text at all.
pub fn network_references(html: &str) -> Vec<String> {
    let lower = html.to_ascii_lowercase();
    let b = lower.as_bytes();
    let mut found = Vec::new();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'-' || c == b'$';
    let snippet = |at: usize| {
        let mut end = (at + 80).min(html.len());
        while !html.is_char_boundary(end) {
            end -= 1;
        }
        html[at..end].split('\n').next().unwrap_or("").to_string()
    };
    let local = |v: &str| {
        let v = v.trim().trim_matches(|c| c == '"' || c == '\'').trim();
        v.starts_with("data:") || v.starts_with('#')
    };
    let occurrences = |pat: &'static str| lower.match_indices(pat).map(|(i, _)| i).collect::<Vec<_>>();

    // Attributes (and script assignments such as `img.src = x`).
    for name in ["src", "href", "srcset", "poster", "action", "formaction", "background"] {
        for i in occurrences(name) {
            if i > 0 && ident(b[i - 1]) || b.get(i + name.len()).is_some_and(|&c| ident(c)) {
                continue;
            }
            let mut j = i + name.len();
            while j < b.len() && b[j].is_ascii_whitespace() {
                j += 1;
            }
            if b.get(j) != Some(&b'=') || b.get(j + 1) == Some(&b'=') {
                continue;
            }
            j += 1;
            while j < b.len() && b[j].is_ascii_whitespace() {
                j += 1;
            }
            let value = match b.get(j) {
                Some(&q @ (b'"' | b'\'')) => {
                    let end = lower[j + 1..].find(q as char).map_or(b.len(), |e| j + 1 + e);
                    &lower[j + 1..end]
                }
                _ => {
                    let end = lower[j..]
                        .find(|c: char| c.is_whitespace() || c == '>' || c == ';' || c == ')')
                        .map_or(b.len(), |e| j + e);
                    &lower[j..end]
                }
            };
            if !local(value) {
                found.push(snippet(i));
            }
        }
    }
    for i in occurrences("url(") {
        let end = lower[i..].find(')').map_or(b.len(), |e| i + e);
        if !local(&lower[i + 4..end]) {
            found.push(snippet(i));
        }
    }
    for i in occurrences("@import") {
        found.push(snippet(i));
    }
    for i in occurrences("fetch(") {
        if i > 0 && ident(b[i - 1]) {
            continue;
        }
        let arg = lower[i + 6..].trim_start();
        let literal_data = arg.starts_with("\"data:") || arg.starts_with("'data:") || arg.starts_with("`data:");
        if !literal_data {
            found.push(snippet(i));
        }
    }
    for pat in ["xmlhttprequest", "websocket", "eventsource", "sendbeacon", "importscripts", "new worker(", "://"] {
        for i in occurrences(pat) {
            if pat == "://" {
                let start = lower[..i].rfind(|c: char| !c.is_ascii_alphabetic()).map_or(0, |s| s + 1);
                if !matches!(&lower[start..i], "http" | "https" | "ws" | "wss" | "ftp") {
                    continue;
                }
                found.push(snippet(start));
            } else {
                found.push(snippet(i));
            }
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::rgbe::tests::{hash01, within_rgbe};
    use super::*;

    fn gradient(w: u32, h: u32, seed: u64, noise: f32) -> Vec<[f32; 3]> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
                let n = 1.0 + noise * (hash01(seed * 1_000_003 + i as u64) - 0.5);
                [x * 4.0 * n, y * n, (x * y * 20.0 + 0.01) * n]
            })
            .collect()
    }

    struct Sample {
        pixels: Vec<Vec<[f32; 3]>>,
        labels: Vec<&'static str>,
    }

    fn sample(w: u32, h: u32) -> Sample {
        Sample {
            pixels: (0..4).map(|k| gradient(w, h, k, if k == 0 { 0.0 } else { 0.3 })).collect(),
            labels: vec!["reference", "unweighted", "MIS <balance> & \"co\"", "ours"],
        }
    }

    const SVG: &str = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg width=\"200\" height=\"100\" \
        viewBox=\"0 0 200 100\" xmlns=\"http://www.w3.org/2000/svg\" xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n\
        <rect x=\"0\" y=\"0\" width=\"200\" height=\"100\" fill=\"#FFFFFF\"/>\n<polyline fill=\"none\" \
        stroke=\"#000\" points=\"0,0 10,10\"/>\n<text x=\"5\" y=\"50\">MSE</text>\n</svg>\n";

    fn input<'a>(s: &'a Sample, w: u32, h: u32, table: &'a str) -> PageInput<'a> {
        let image = |k: usize| PageImage { label: s.labels[k], width: w, height: h, pixels: &s.pixels[k] };
        PageInput {
            title: "Fog <test> page",
            reference: image(0),
            images: (1..s.labels.len()).map(image).collect(),
            table_html: table,
            plot_svg: Some(SVG),
            notes: "Equal time.\nLower is better & so on.",
        }
    }

    fn table() -> String {
        html_table(
            &["estimator", "MSE", "time s"],
            &[("unweighted", vec!["1.0".into(), "2".into()]), ("ours", vec!["0.5".into(), "2".into()])],
        )
    }

    /// Checks that tags nest: void elements and `/>` close themselves; the content of script
    /// and style elements and comments is skipped.
    fn check_balanced(html: &str) -> Result<usize, String> {
        const VOID: [&str; 14] = [
            "area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr",
            "param",
        ];
        let mut stack: Vec<String> = Vec::new();
        let mut count = 0;
        let mut i = 0;
        while let Some(off) = html[i..].find('<') {
            let at = i + off;
            let rest = &html[at..];
            if rest.starts_with("<!--") {
                i = at + rest.find("-->").ok_or("unclosed comment")? + 3;
                continue;
            }
            if rest.starts_with("<!") || rest.starts_with("<?") {
                i = at + rest.find('>').ok_or("unclosed declaration")? + 1;
                continue;
            }
            // The end of the tag, skipping quoted attribute values.
            let bytes = rest.as_bytes();
            let (mut j, mut quote) = (1, None);
            while j < bytes.len() {
                match (quote, bytes[j]) {
                    (None, b'"' | b'\'') => quote = Some(bytes[j]),
                    (Some(q), c) if c == q => quote = None,
                    (None, b'>') => break,
                    _ => {}
                }
                j += 1;
            }
            if j >= bytes.len() {
                return Err(format!("unclosed tag at {at}"));
            }
            let tag = &rest[1..j];
            i = at + j + 1;
            if let Some(name) = tag.strip_prefix('/') {
                let name = name.trim().to_ascii_lowercase();
                match stack.pop() {
                    Some(open) if open == name => {}
                    other => return Err(format!("</{name}> closes {other:?} at {at}")),
                }
                continue;
            }
            let name: String =
                tag.chars().take_while(|c| !c.is_whitespace() && *c != '/').collect::<String>().to_ascii_lowercase();
            if name.is_empty() {
                return Err(format!("bad tag at {at}"));
            }
            count += 1;
            if tag.ends_with('/') || VOID.contains(&name.as_str()) {
                continue;
            }
            if name == "script" || name == "style" {
                let close = format!("</{name}>");
                i += html[i..].to_ascii_lowercase().find(&close).ok_or(format!("unclosed {name}"))? + close.len();
                continue;
            }
            stack.push(name);
        }
        if stack.is_empty() { Ok(count) } else { Err(format!("unclosed: {stack:?}")) }
    }

    fn base64_decode(s: &str) -> Vec<u8> {
        let val = |c: u8| match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => panic!("not base64: {c}"),
        } as u32;
        let mut out = Vec::new();
        for chunk in s.as_bytes().chunks(4) {
            let n = chunk.iter().take_while(|&&c| c != b'=').count();
            let v = chunk[..n].iter().enumerate().fold(0, |acc, (k, &c)| acc | val(c) << (18 - 6 * k));
            out.extend_from_slice(&[(v >> 16) as u8, (v >> 8) as u8, v as u8][..n - 1]);
        }
        out
    }

    /// The JSON block of a page: from its `<script>` tag to the first `</script` after it, where
    /// an HTML parser ends the element whatever the JSON says.
    fn page_data(html: &str) -> serde_json::Value {
        const OPEN: &str = "<script type=\"application/json\" id=\"fog-data\">";
        let start = html.find(OPEN).expect("a data block") + OPEN.len();
        let end = start + html[start..].to_ascii_lowercase().find("</script").expect("its end");
        serde_json::from_str(&html[start..end]).expect("the data block is JSON")
    }

    /// The images of a page, read back as its JavaScript reads them.
    fn page_images(html: &str) -> Vec<(String, Vec<[f32; 3]>)> {
        let data = page_data(html);
        let (w, h) = (data["width"].as_u64().unwrap() as u32, data["height"].as_u64().unwrap() as u32);
        let images = data["images"].as_array().unwrap();
        images
            .iter()
            .map(|image| {
                let png = base64_decode(image["png"].as_str().unwrap());
                let (pw, ph, pixels) = rgbe::decode_png(&png).unwrap();
                assert_eq!((pw, ph), (w, h));
                (image["label"].as_str().unwrap().to_string(), pixels)
            })
            .collect()
    }

    /// The plot of a page: the SVG inside its `data:` URI.
    fn page_plot(html: &str) -> Option<String> {
        const OPEN: &str = "<img src=\"data:image/svg+xml;base64,";
        let start = html.find(OPEN)? + OPEN.len();
        let end = start + html[start..].find('"').unwrap();
        Some(String::from_utf8(base64_decode(&html[start..end])).unwrap())
    }

    #[test]
    fn page_holds_every_label_title_table_and_plot() {
        let s = sample(16, 9);
        let t = table();
        let html = comparison_page(&input(&s, 16, 9, &t)).unwrap();
        for label in &s.labels {
            assert!(html.contains(&escape_html(label)), "missing {label}");
        }
        assert!(html.contains("MIS &lt;balance&gt; &amp; &quot;co&quot;"));
        assert!(html.contains("\"label\":\"MIS \\u003cbalance\\u003e \\u0026 \\\"co\\\"\""));
        assert!(html.contains("<title>Fog &lt;test&gt; page</title>"));
        assert!(html.contains("Lower is better &amp; so on."));
        assert!(html.contains("<th scope=\"row\">ours</th>"));
        assert_eq!(page_plot(&html).as_deref(), Some(SVG));
        assert!(html.contains("<kbd>1</kbd><span>reference</span>"));
        assert!(html.contains("<kbd>4</kbd><span>ours</span>"));
        assert!(!html.contains("<?xml") && !html.contains("{{"));
    }

    #[test]
    fn page_tags_are_balanced() {
        let s = sample(16, 9);
        let t = table();
        let html = comparison_page(&input(&s, 16, 9, &t)).unwrap();
        let n = check_balanced(&html).unwrap();
        assert!(n > 50, "only {n} tags");
        // The checker itself catches slips.
        assert!(check_balanced("<div><span></div></span>").is_err());
        assert!(check_balanced("<div><p>text</p>").is_err());
        assert!(check_balanced("<div><br><svg><rect/></svg></div>").is_ok());
    }

    #[test]
    fn page_has_no_network_references() {
        let s = sample(16, 9);
        let t = table();
        let html = comparison_page(&input(&s, 16, 9, &t)).unwrap();
        assert_eq!(network_references(&html), Vec::<String>::new());
        assert!(!html.contains("http://") && !html.contains("https://"));
        assert!(!html.contains("xmlns"));
    }

    #[test]
    fn network_references_finds_outside_loads() {
        let bad = [
            "<img src=\"pic.png\">",
            "<img SRC = 'https://x.test/a.png'>",
            "<script src=//cdn.test/x.js></script>",
            "<link rel=stylesheet href=\"style.css\">",
            "<image xlink:href=\"a.png\"/>",
            "<div style=\"background: url(a.png)\">",
            "<style>@import 'a.css';</style>",
            "<script>fetch(url)</script>",
            "<script>fetch('https://x.test')</script>",
            "<script>new XMLHttpRequest()</script>",
            "<script>new WebSocket(u)</script>",
            "<script>img.src = name;</script>",
            "<p>see https://x.test</p>",
            "<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>",
        ];
        for b in bad {
            assert!(!network_references(b).is_empty(), "missed {b}");
        }
        let good = [
            "<img src=\"data:image/png;base64,AAAA\">",
            "<a href=\"#results\">results</a>",
            "<use xlink:href='#g1'/>",
            "<div style=\"background:url('data:image/png;base64,AA')\">",
            "<script>fetch('data:application/octet-stream;base64,AA')</script>",
            "<script>const srcCanvas = 1; if (a.src === b) {} data-src=\"x\"</script>",
            "<p>the sources, the hrefs</p>",
        ];
        for g in good {
            assert_eq!(network_references(g), Vec::<String>::new(), "flagged {g}");
        }
    }

    #[test]
    fn caller_content_with_outside_references_is_refused() {
        let s = sample(4, 4);
        let t = "<table><tr><td><img src=\"logo.png\"></td></tr></table>";
        let err = comparison_page(&input(&s, 4, 4, t)).unwrap_err();
        assert!(matches!(err, PageError::ExternalReference(ref r) if r[0].contains("logo.png")), "{err}");
        let t = table();
        let mut i = input(&s, 4, 4, &t);
        i.notes = "see https://x.test";
        assert!(matches!(comparison_page(&i), Err(PageError::ExternalReference(_))));
        // The plot is an image, which loads nothing: its text is neither searched nor visible.
        let mut i = input(&s, 4, 4, &t);
        i.plot_svg = Some("<svg xmlns=\"http://www.w3.org/2000/svg\"><image href=\"https://x.test/p.png\"/></svg>");
        let html = comparison_page(&i).unwrap();
        assert_eq!(network_references(&html), Vec::<String>::new());
    }

    #[test]
    fn the_plot_is_the_callers_svg_unchanged() {
        let s = sample(4, 4);
        let t = table();
        let html = comparison_page(&input(&s, 4, 4, &t)).unwrap();
        assert_eq!(page_plot(&html).as_deref(), Some(SVG));
        assert_eq!(html.matches("<section id=\"plot\">").count(), 1);
    }

    #[test]
    fn page_images_decode_as_the_javascript_does() {
        let (w, h) = (23, 7);
        let s = sample(w, h);
        let t = table();
        let html = comparison_page(&input(&s, w, h, &t)).unwrap();
        let decoded = page_images(&html);
        assert_eq!(decoded.len(), s.labels.len());
        for (k, (label, pixels)) in decoded.iter().enumerate() {
            assert_eq!(label, s.labels[k]);
            assert_eq!(pixels.len(), (w * h) as usize);
            for (o, d) in s.pixels[k].iter().zip(pixels) {
                assert!(within_rgbe(*o, *d), "{o:?} -> {d:?}");
            }
        }
    }

    #[test]
    fn base64_matches_known_vectors() {
        for (raw, enc) in [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foobar", "Zm9vYmFy")] {
            let s = base64(raw.as_bytes());
            assert_eq!(s, enc);
            assert_eq!(base64_decode(&s), raw.as_bytes());
        }
    }

    #[test]
    fn mismatched_or_malformed_images_are_errors() {
        let s = sample(8, 4);
        let t = table();
        let other = gradient(4, 8, 9, 0.1);
        let mut i = input(&s, 8, 4, &t);
        i.images[1] = PageImage { label: "rotated", width: 4, height: 8, pixels: &other };
        assert_eq!(
            comparison_page(&i).unwrap_err(),
            PageError::SizeMismatch { label: "rotated".into(), size: (4, 8), reference: (8, 4) }
        );
        let mut i = input(&s, 8, 4, &t);
        i.images[0].pixels = &s.pixels[1][..31];
        assert!(matches!(comparison_page(&i), Err(PageError::PixelCount { pixels: 31, .. })));
        let mut i = input(&s, 8, 4, &t);
        i.reference = PageImage { label: "empty", width: 0, height: 4, pixels: &[] };
        assert!(matches!(comparison_page(&i), Err(PageError::Empty { .. })));
        let mut i = input(&s, 8, 4, &t);
        i.reference.width = MAX_SIDE + 1;
        assert!(matches!(comparison_page(&i), Err(PageError::TooLarge { .. })));
        // Messages name the image.
        let e = PageError::SizeMismatch { label: "x".into(), size: (1, 2), reference: (3, 4) };
        assert_eq!(e.to_string(), "image \"x\" is 1x2, the reference 3x4");
    }

    #[test]
    fn a_page_with_only_the_reference_works() {
        let s = sample(4, 4);
        let t = table();
        let mut i = input(&s, 4, 4, &t);
        i.images.clear();
        i.plot_svg = None;
        let html = comparison_page(&i).unwrap();
        check_balanced(&html).unwrap();
        assert_eq!(page_images(&html).len(), 1);
        assert!(page_plot(&html).is_none() && !html.contains("id=\"plot\""));
    }

    #[test]
    fn labels_cannot_end_the_data_block() {
        let s = sample(4, 4);
        let t = table();
        let labels = [
            "\"quoted\" \\ back\tslash\u{1}",
            "</script><script>alert(1)</script>",
            "<!--<script>",
            "</SCRIPT >&amp; line\u{2028}para\u{2029}end",
        ];
        let mut i = input(&s, 4, 4, &t);
        i.reference.label = labels[0];
        for (image, label) in i.images.iter_mut().zip(&labels[1..]) {
            image.label = label;
        }
        let html = comparison_page(&i).unwrap();
        // The data block ends where it should, holds every label as it was, and has no `<`.
        let read: Vec<String> = page_images(&html).into_iter().map(|(label, _)| label).collect();
        assert_eq!(read, labels);
        let start = html.find("id=\"fog-data\">").unwrap();
        let block = &html[start..start + html[start..].find("</script>").unwrap()];
        assert!(!block[15..].contains(['<', '>', '&', '\u{2028}', '\u{2029}']), "{}", &block[..200.min(block.len())]);
        // Exactly the page's own two scripts, and the tags still nest.
        assert_eq!(html.to_ascii_lowercase().matches("<script").count(), 2);
        assert_eq!(html.to_ascii_lowercase().matches("</script").count(), 2);
        check_balanced(&html).unwrap();
    }

    #[test]
    fn script_json_escapes_what_html_would_read_and_stays_json() {
        let text = "</script>&<!--\u{2028}\u{2029}\"\\é";
        let json = script_json(&text).unwrap();
        assert_eq!(json, "\"\\u003c/script\\u003e\\u0026\\u003c!--\\u2028\\u2029\\\"\\\\é\"");
        assert_eq!(serde_json::from_str::<String>(&json).unwrap(), text);
        let data = PageData { width: 3, height: 2, images: vec![EncodedImage { label: "a<b", png: "AA==".into() }] };
        assert_eq!(
            script_json(&data).unwrap(),
            r#"{"width":3,"height":2,"images":[{"label":"a\u003cb","png":"AA=="}]}"#
        );
    }

    #[test]
    fn the_template_has_every_slot_and_only_known_ones() {
        let mut slots: Vec<&str> = TEMPLATE.split("{{").skip(1).map(|s| &s[..s.find("}}").unwrap()]).collect();
        slots.sort_unstable();
        assert_eq!(slots, ["buttons", "css", "data", "js", "notes", "plot", "table", "title", "title"]);
        // A part's own text is not searched for slots.
        assert_eq!(fill("a{{x}}b{{y}}c", &[("x", "{{y}}"), ("y", "Y")]), "a{{y}}bYc");
        // The style and script hold no slot markers that could be mistaken for them.
        assert!(!CSS.contains("{{") && !JS.contains("{{"));
    }

    #[test]
    fn the_page_files_refer_to_nothing_outside() {
        for (name, text) in [("viewer.html", TEMPLATE), ("viewer.css", CSS), ("viewer.js", JS)] {
            assert_eq!(network_references(text), Vec::<String>::new(), "{name}");
        }
    }

    #[test]
    fn the_page_is_its_template_filled() {
        let s = sample(4, 4);
        let t = table();
        let html = comparison_page(&input(&s, 4, 4, &t)).unwrap();
        // Every piece of the template is in the page, in order.
        let mut at = 0;
        for piece in TEMPLATE.split("{{").flat_map(|s| s.split_once("}}").map_or(s, |(_, rest)| rest).lines()) {
            let found = html[at..].find(piece).unwrap_or_else(|| panic!("missing {piece:?}"));
            at += found + piece.len();
        }
        assert!(
            html.contains(&format!("<style>\n{CSS}</style>")) && html.contains(&format!("<script>\n{JS}</script>"))
        );
        let order: Vec<usize> =
            ["<header>", "id=\"viewer\"", "id=\"results\"", "id=\"plot\"", "id=\"fog-data\"", "<script>\n"]
                .iter()
                .map(|m| html.find(m).unwrap_or_else(|| panic!("no {m}")))
                .collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{order:?}");
    }
}
