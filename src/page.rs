//! `index.html`: a self-contained, offline, interactive comparison page for the `table` command.
//!
//! The page shows one image at a time in a large view (the reference or one estimator), flips
//! between them with buttons and the number keys, zooms with pixel-exact magnification, pans,
//! changes exposure, and shows beside it the chosen estimator's false-colour per-pixel error
//! against the reference, with the same zoom and pan. Under the cursor it reads out the pixel
//! values. The table and the error-versus-time plot follow below.
//!
//! Everything is in the one HTML string: the CSS and JavaScript are written out below (readable,
//! commented), the plot is inlined SVG, and the images travel as base64 PNGs inside a JSON
//! block. Nothing is fetched: the page holds no `http://` or `https://` text at all (the
//! plot's `xmlns` attributes are dropped, which inline SVG in HTML does not need), and a
//! Content-Security-Policy forbids every network load.
//!
//! # Image encoding
//!
//! Each image keeps its full dynamic range as Radiance RGBE (one shared exponent per pixel,
//! 8-bit mantissas): `value = (mantissa + 0.5) * 2^(E - 136)`, `E = 0` meaning black. The four
//! bytes of every pixel are laid out as four planes of one 8-bit greyscale PNG of 2W x 2H:
//!
//! ```text
//! +-------+-------+
//! |   R   |   G   |     each plane W x H, row-major, top row first
//! +-------+-------+
//! |   B   |   E   |
//! +-------+-------+
//! ```
//!
//! A greyscale PNG is opaque, so no browser premultiplies anything, and an untagged PNG decoded
//! with `colorSpaceConversion: 'none'` reaches `getImageData` byte for byte; the JavaScript
//! then undoes RGBE into a `Float32Array`. Planes compress better than interleaved bytes.
//! Precision: each channel comes back within `max(r, g, b) / 256` of its value (so the
//! brightest channel within 0.4 %); values below 2^-128 become 0; negative and NaN values
//! become 0 and +inf the largest RGBE value (about 1.7e38).

use std::fmt;

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
    /// The error-versus-time plot as SVG, inlined (an XML prolog and `xmlns` attributes are
    /// dropped).
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
    /// The caller's table, plot or notes refer to something outside the page (see
    /// [`network_references`]).
    ExternalReference(Vec<String>),
    /// The PNG encoder failed.
    Encode(String),
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
        }
    }
}

impl std::error::Error for PageError {}

/// The largest width or height the page takes: the encoded PNG is twice as wide and high, and
/// browsers cap canvases at 16384 (some) to 32767 pixels a side.
pub const MAX_SIDE: u32 = 8192;

/// The page: one HTML string.
pub fn comparison_page(input: &PageInput) -> Result<String, PageError> {
    let size = (input.reference.width, input.reference.height);
    let all: Vec<&PageImage> = std::iter::once(&input.reference).chain(&input.images).collect();
    for image in &all {
        check_image(image, size)?;
    }

    // The page is `head_and_body` + the image payload + `tail`; the caller's parts are checked
    // for outside references before the (large, base64-only) payload goes in.
    let mut page = String::with_capacity(64 * 1024);
    page.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    page.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
    // Belt and braces: even a slip in the caller's HTML cannot make the page load anything.
    page.push_str(
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; \
         img-src data: blob:; style-src 'unsafe-inline'; script-src 'unsafe-inline'\">\n",
    );
    page.push_str(&format!("<title>{}</title>\n<style>\n{CSS}</style>\n</head>\n<body>\n", escape_html(input.title)));
    page.push_str(&format!("<header>\n<h1>{}</h1>\n", escape_html(input.title)));
    if !input.notes.trim().is_empty() {
        page.push_str(&format!("<p class=\"notes\">{}</p>\n", escape_html(input.notes.trim())));
    }
    page.push_str("</header>\n<main>\n");
    viewer_html(&mut page, &all);
    page.push_str("<section id=\"results\">\n<h2>Results</h2>\n<div class=\"table-wrap\">\n");
    page.push_str(input.table_html);
    page.push_str("\n</div>\n<p class=\"hint\">Click a row to show that estimator above.</p>\n</section>\n");
    if let Some(svg) = input.plot_svg {
        page.push_str("<section id=\"plot\">\n<h2>Error versus time</h2>\n<figure class=\"plot\">\n");
        page.push_str(&inline_svg(svg));
        page.push_str("\n</figure>\n</section>\n");
    }
    page.push_str("</main>\n<script type=\"application/json\" id=\"fog-data\">");
    let tail = format!("</script>\n<script>\n{JS}</script>\n</body>\n</html>\n");

    let mut refs = network_references(&page);
    refs.extend(network_references(&tail));
    if !refs.is_empty() {
        return Err(PageError::ExternalReference(refs));
    }

    // The payload: {"width":W,"height":H,"images":[{"label":..,"png":base64}, ...]}.
    let pngs = all.iter().map(|image| encode_rgbe_png(image)).collect::<Result<Vec<_>, _>>()?;
    page.reserve(pngs.iter().map(|p| p.len() * 4 / 3 + 64).sum::<usize>() + tail.len());
    page.push_str(&format!("{{\"width\":{},\"height\":{},\"images\":[", size.0, size.1));
    for (i, (image, png)) in all.iter().zip(&pngs).enumerate() {
        if i > 0 {
            page.push(',');
        }
        page.push_str(&format!("\n{{\"label\":{},\"png\":\"", json_string(image.label)));
        base64_into(png, &mut page);
        page.push_str("\"}");
    }
    page.push_str("\n]}");
    page.push_str(&tail);
    Ok(page)
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

/// The buttons, controls and the two views.
fn viewer_html(page: &mut String, all: &[&PageImage]) {
    page.push_str(
        "<section id=\"viewer\" class=\"viewer\" data-current=\"0\" data-ready=\"false\">\n\
         <div class=\"choices\" role=\"toolbar\" aria-label=\"Images\">\n",
    );
    for (i, image) in all.iter().enumerate() {
        let key = match i {
            0..=8 => format!("<kbd>{}</kbd>", i + 1),
            9 => "<kbd>0</kbd>".to_string(),
            _ => String::new(),
        };
        let class = if i == 0 { " class=\"reference\"" } else { "" };
        page.push_str(&format!(
            "<button type=\"button\" data-index=\"{i}\"{class} aria-pressed=\"{}\">{key}<span>{}</span></button>\n",
            i == 0,
            escape_html(image.label)
        ));
    }
    page.push_str(VIEWER_HTML);
}

/// The controls, views and readout (the buttons come before).
const VIEWER_HTML: &str = r##"</div>
<div class="controls">
  <label title="Exposure in stops (E / Shift+E, R resets)">Exposure
    <input type="range" id="exposure" min="-10" max="10" step="0.25" value="0">
    <output id="exposure-value">+0.00 EV</output></label>
  <span class="zoom">Zoom <output id="zoom-value">fit</output>
    <button type="button" id="zoom-out" title="Zoom out (-)">&minus;</button><button type="button" id="zoom-in" title="Zoom in (+)">+</button><button type="button" id="fit" title="Fit (F)">Fit</button></span>
  <label title="Per-pixel error metric (M)">Error
    <select id="metric">
      <option value="smape">SMAPE |e&minus;r|/(|e|+|r|)</option>
      <option value="relative">relative |e&minus;r|/(r+0.01)</option>
    </select></label>
  <label title="Colour scale of the error view">Scale <select id="range"></select></label>
  <label title="Show the error view (X)"><input type="checkbox" id="show-error" checked> error view</label>
</div>
<div class="views">
  <figure class="view" id="image-view">
    <figcaption><span class="caption-label" id="image-label"></span><span class="caption-note" id="image-note"></span></figcaption>
    <canvas class="view-canvas" aria-label="Selected image"></canvas>
  </figure>
  <figure class="view" id="error-view">
    <figcaption><span class="caption-label" id="error-label"></span>
      <span class="colorbar"><canvas id="colorbar" width="256" height="1"></canvas><span class="ticks" id="ticks"></span><span class="marker" id="marker" hidden></span></span></figcaption>
    <canvas class="view-canvas" aria-label="Error against the reference"></canvas>
  </figure>
  <div class="loading" id="loading">Decoding images&hellip;</div>
</div>
<div class="readout" id="readout"></div>
<p class="help"><kbd>1</kbd>&ndash;<kbd>9</kbd> <kbd>0</kbd> choose an image (<kbd>1</kbd> is the reference) &middot; <kbd>&larr;</kbd> <kbd>&rarr;</kbd> previous / next &middot; wheel or <kbd>+</kbd> <kbd>&minus;</kbd> zoom &middot; drag to pan &middot; <kbd>F</kbd> or double-click: fit &middot; <kbd>E</kbd> / <kbd>Shift</kbd>+<kbd>E</kbd> exposure &plusmn;&frac12; stop, <kbd>R</kbd> reset &middot; <kbd>X</kbd> error view &middot; <kbd>M</kbd> error metric</p>
<noscript><p class="help">The image viewer needs JavaScript; the table and the plot below do not.</p></noscript>
</section>
"##;

/// The plot, ready to inline: no XML prolog or doctype, no `xmlns` attributes (the HTML parser
/// puts `<svg>` in the SVG namespace by itself, and the namespace names are URLs).
fn inline_svg(svg: &str) -> String {
    let mut s = svg.trim();
    for (open, close) in [("<?xml", "?>"), ("<!DOCTYPE", ">"), ("<!doctype", ">")] {
        if let Some(rest) = s.strip_prefix(open) {
            s = rest.find(close).map_or("", |i| rest[i + close.len()..].trim_start());
        }
    }
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    // Drop ` xmlns="..."` and ` xmlns:prefix="..."` wherever they are.
    while let Some(i) = rest.find(" xmlns") {
        out.push_str(&rest[..i]);
        let after = &rest[i + 6..];
        let name_end = after.find(|c: char| c == '=' || c.is_whitespace() || c == '>').unwrap_or(after.len());
        let name_ok = after[..name_end].is_empty() || after[..name_end].starts_with(':');
        let value = after[name_end..].strip_prefix('=').and_then(|v| {
            let q = v.chars().next().filter(|&q| q == '"' || q == '\'')?;
            v[1..].find(q).map(|end| &v[end + 2..])
        });
        match (name_ok, value) {
            (true, Some(remaining)) => rest = remaining,
            _ => {
                out.push_str(" xmlns");
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

// ---------------------------------------------------------------------------------------------
// RGBE

/// The Radiance RGBE bytes of one linear RGB pixel (see the module's doc for the precision).
pub fn rgbe_encode(rgb: [f32; 3]) -> [u8; 4] {
    // Largest value RGBE holds: mantissa 255 (+0.5 on decoding) at E = 255.
    const MAX: f64 = 255.0 * (1u128 << 119) as f64; // mantissa 255 at E = 255: 255 * 2^(255 - 136)
    let c = rgb.map(|v| {
        let v = v as f64;
        if v > 0.0 { v.min(MAX) } else { 0.0 } // NaN and negatives: 0; +inf: MAX
    });
    let v = c[0].max(c[1]).max(c[2]);
    if v <= 0.0 {
        return [0; 4];
    }
    // v = f * 2^e with f in [0.5, 1): read e from the f64's exponent bits (v is normal in f64).
    let e = ((v.to_bits() >> 52) & 0x7ff) as i32 - 1022;
    if e + 128 < 1 {
        return [0; 4];
    }
    let scale = 2f64.powi(8 - e);
    let m = c.map(|x| (x * scale).floor().min(255.0) as u8);
    [m[0], m[1], m[2], (e + 128) as u8]
}

/// Linear RGB from RGBE bytes, computed as the page's JavaScript does (in f64, stored as f32).
/// The tests' model of the page's decoding.
#[cfg(test)]
pub fn rgbe_decode(rgbe: [u8; 4]) -> [f32; 3] {
    if rgbe[3] == 0 {
        return [0.0; 3];
    }
    let f = 2f64.powi(rgbe[3] as i32 - 136);
    [0, 1, 2].map(|c| ((rgbe[c] as f64 + 0.5) * f) as f32)
}

/// The 2W x 2H greyscale PNG of an image's RGBE planes (R G / B E).
pub fn encode_rgbe_png(image: &PageImage) -> Result<Vec<u8>, PageError> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let (w, h) = (image.width as usize, image.height as usize);
    let mut planes = vec![0u8; 4 * w * h];
    for y in 0..h {
        for x in 0..w {
            let b = rgbe_encode(image.pixels[y * w + x]);
            let top = y * 2 * w + x;
            let bottom = top + 2 * w * h;
            planes[top] = b[0];
            planes[top + w] = b[1];
            planes[bottom] = b[2];
            planes[bottom + w] = b[3];
        }
    }
    let mut png = Vec::new();
    PngEncoder::new_with_quality(&mut png, CompressionType::Best, FilterType::Adaptive)
        .write_image(&planes, 2 * image.width, 2 * image.height, image::ExtendedColorType::L8)
        .map_err(|e| PageError::Encode(e.to_string()))?;
    Ok(png)
}

/// The linear RGB pixels of a PNG made by [`encode_rgbe_png`], as the page's JavaScript reads
/// them. The tests' model of the page's decoding.
#[cfg(test)]
pub fn decode_rgbe_png(png: &[u8]) -> Result<(u32, u32, Vec<[f32; 3]>), String> {
    let img = image::load_from_memory_with_format(png, image::ImageFormat::Png).map_err(|e| e.to_string())?;
    let grey = img.to_luma8();
    let (w2, h2) = grey.dimensions();
    if w2 % 2 != 0 || h2 % 2 != 0 {
        return Err(format!("{w2}x{h2} is not 2W x 2H"));
    }
    let (w, h) = (w2 / 2, h2 / 2);
    let g = |x: u32, y: u32| grey.get_pixel(x, y).0[0];
    let mut pixels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            pixels.push(rgbe_decode([g(x, y), g(x + w, y), g(x, y + h), g(x + w, y + h)]));
        }
    }
    Ok((w, h, pixels))
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

/// A JSON string literal that is also safe inside a `<script>` element.
fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '<' | '>' | '&' | '\u{2028}' | '\u{2029}' => out.push_str(&format!("\\u{:04x}", c as u32)),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn base64_into(bytes: &[u8], out: &mut String) {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
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
}

/// Everything in `html` that would make a browser reach outside the page: `src=`, `href=`
/// (also `xlink:href=`), `srcset=`, `poster=`, `action=`, `formaction=`, `background=` and CSS
/// `url(...)` whose value is not `data:` or `#...`; any `@import`; `fetch(` of anything but a
/// `data:` literal; `XMLHttpRequest`, `WebSocket`, `EventSource`, `sendBeacon`,
/// `importScripts`, `new Worker(`; and any absolute `http://`, `https://`, `ws://`, `wss://` or
/// `ftp://` URL text at all (the page holds none, not even an SVG `xmlns`).
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

// ---------------------------------------------------------------------------------------------
// CSS and JavaScript

const CSS: &str = r##"/* ---- Base: system fonts, a dark theme (images are judged against dark surroundings) ---- */
:root {
  color-scheme: dark;
  --bg: #15171b;
  --surface: #1d2026;
  --surface-2: #262a32;
  --border: #343a44;
  --fg: #e7e8ea;
  --muted: #9aa1ac;
  --accent: #5aa9ff;
  --accent-fg: #07121f;
  --view-bg: #08090b;
  --mono: ui-monospace, SFMono-Regular, Menlo, Consolas, "DejaVu Sans Mono", "Liberation Mono", monospace;
}
* { box-sizing: border-box; }
body {
  margin: 0;
  background: var(--bg);
  color: var(--fg);
  font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial,
        "Noto Sans", "Liberation Sans", sans-serif;
}
header, main > section { max-width: 1680px; margin: 0 auto; padding: 0 20px; }
header { padding-top: 16px; }
h1 { font-size: 1.4rem; font-weight: 600; margin: 0 0 4px; }
h2 { font-size: 1.1rem; font-weight: 600; margin: 28px 0 10px; }
.notes { color: var(--muted); white-space: pre-line; max-width: 90ch; margin: 0 0 6px; }
kbd {
  font: 0.78em var(--mono);
  padding: 1px 5px;
  border-radius: 4px;
  background: rgba(255, 255, 255, 0.1);
  border: 1px solid rgba(255, 255, 255, 0.2);
}

/* ---- Image buttons: one per image, with its number key ---- */
.choices { display: flex; flex-wrap: wrap; gap: 6px; margin: 10px 0 8px; }
.choices button, .controls button {
  font: inherit;
  color: var(--fg);
  background: var(--surface-2);
  border: 1px solid var(--border);
  border-radius: 6px;
  padding: 4px 10px;
  cursor: pointer;
}
.choices button { display: inline-flex; align-items: center; gap: 7px; }
.choices button:hover, .controls button:hover { border-color: var(--muted); }
.choices button[aria-pressed="true"] {
  background: var(--accent);
  border-color: var(--accent);
  color: var(--accent-fg);
  font-weight: 600;
}
.choices button[aria-pressed="true"] kbd { background: rgba(0, 0, 0, 0.15); border-color: rgba(0, 0, 0, 0.3); }
/* The estimator whose error the error view shows, while another image is selected. */
.choices button.error-target:not([aria-pressed="true"]) { box-shadow: inset 0 -3px 0 #fde725; }

/* ---- Controls ---- */
.controls {
  display: flex; flex-wrap: wrap; align-items: center; gap: 8px 22px;
  margin-bottom: 10px; color: var(--muted); font-size: 0.9rem;
}
.controls label, .controls .zoom { display: inline-flex; align-items: center; gap: 7px; }
.controls button { padding: 1px 9px; }
.controls select {
  font: inherit; color: var(--fg); background: var(--surface-2);
  border: 1px solid var(--border); border-radius: 5px; padding: 2px 4px;
}
.controls input[type="range"] { width: 150px; accent-color: var(--accent); }
output { font-family: var(--mono); color: var(--fg); min-width: 5.5em; }
#zoom-value { min-width: 3em; }

/* ---- The two views, side by side, sharing zoom and pan ---- */
.views { position: relative; display: flex; gap: 10px; }
.view {
  flex: 1 1 0; min-width: 0; margin: 0;
  display: flex; flex-direction: column;
  background: var(--surface); border: 1px solid var(--border); border-radius: 8px; overflow: hidden;
}
.view figcaption {
  display: flex; align-items: center; justify-content: space-between; gap: 12px;
  min-height: 44px; padding: 4px 12px; font-size: 0.92rem;
}
.caption-label { font-weight: 600; overflow: hidden; text-overflow: ellipsis; white-space: nowrap; }
.caption-note { color: var(--muted); font-size: 0.85rem; white-space: nowrap; }
canvas.view-canvas {
  display: block; width: 100%; height: clamp(240px, 64vh, 960px);
  background: var(--view-bg);
  image-rendering: pixelated;      /* never smooth magnified pixels */
  cursor: crosshair; touch-action: none;
}
canvas.view-canvas.dragging { cursor: grabbing; }
.viewer[data-error="off"] #error-view { display: none; }
.loading {
  position: absolute; inset: 44px 0 0 0; display: grid; place-items: center;
  color: var(--muted); pointer-events: none;
}
.viewer[data-ready="true"] .loading { display: none; }

/* ---- Colour bar of the error view ---- */
.colorbar { position: relative; display: flex; flex-direction: column; width: min(280px, 45%); flex: none; }
#colorbar { display: block; width: 100%; height: 10px; border-radius: 2px; image-rendering: auto; }
.ticks { position: relative; height: 15px; font: 11px/15px var(--mono); color: var(--muted); }
.ticks span { position: absolute; top: 0; transform: translateX(-50%); white-space: nowrap; }
.ticks span:first-child { transform: none; }
.ticks span:last-child { transform: translateX(-100%); }
.marker {   /* where the error under the cursor sits on the bar */
  position: absolute; top: -3px; width: 2px; height: 16px; margin-left: -1px;
  background: #fff; box-shadow: 0 0 0 1px #000;
}

/* ---- Pixel readout and help ---- */
.readout {
  display: flex; flex-wrap: wrap; align-items: center; gap: 4px 18px;
  min-height: 2.2em; padding: 6px 2px 0;
  font: 0.84rem var(--mono); color: var(--muted);
}
.readout b { color: var(--fg); font-weight: 600; }
.swatch {
  display: inline-block; width: 0.9em; height: 0.9em; margin-right: 6px;
  vertical-align: -0.1em; border: 1px solid rgba(255, 255, 255, 0.35);
}
.help, .hint { color: var(--muted); font-size: 0.84rem; margin: 6px 0 0; }

/* ---- Table and plot ---- */
.table-wrap { overflow-x: auto; border: 1px solid var(--border); border-radius: 8px; }
#results table { border-collapse: collapse; width: 100%; font-size: 0.88rem; font-variant-numeric: tabular-nums; }
#results th, #results td {
  padding: 6px 10px; text-align: right; white-space: nowrap;
  border-bottom: 1px solid var(--border);
}
#results th:first-child, #results td:first-child { text-align: left; }
#results thead th { background: var(--surface-2); font-weight: 600; white-space: normal; vertical-align: bottom; }
#results tbody th { font-weight: 500; }
#results tbody tr:last-child > * { border-bottom: none; }
#results tbody tr:hover { background: rgba(255, 255, 255, 0.04); }
#results tr.selectable { cursor: pointer; }
#results tr.current { background: rgba(90, 169, 255, 0.16); }
.plot { display: inline-block; max-width: 100%; margin: 0 0 28px; padding: 10px; background: #fff; border-radius: 8px; }
.plot svg { display: block; max-width: 100%; height: auto; }

@media (max-width: 900px) {
  .views { flex-direction: column; }
  canvas.view-canvas { height: 46vh; }
}
"##;

const JS: &str = r##""use strict";
/*
 * The comparison viewer.
 *
 * Images arrive in the JSON block #fog-data: {width, height, images: [{label, png}]}, where
 * images[0] is the reference and `png` is a base64 greyscale PNG of 2W x 2H holding the
 * image's Radiance RGBE bytes as four planes:  R G / B E.  A pixel's linear value is
 * (mantissa + 0.5) * 2^(E - 136), and E = 0 means black. An opaque greyscale PNG decoded with
 * colorSpaceConversion 'none' reaches getImageData unchanged, so the floats come back exactly
 * as the page's writer encoded them.
 *
 * Both views are canvases the size of their box in device pixels. Each redraw copies the
 * source canvas (the tone-mapped image, or the false-colour error) with smoothing off, at
 * `zoom` device pixels per image pixel (an integer from 1 up) and at an origin rounded to whole
 * device pixels, so magnified pixels are exact squares. Both views share zoom and the image
 * point at their centre, so they pan and zoom together.
 */
(function () {
  const data = JSON.parse(document.getElementById("fog-data").textContent);
  const W = data.width, H = data.height;
  const images = data.images;            // [{label, png}]; images[0] is the reference
  const N = images.length;
  const $ = (id) => document.getElementById(id);
  const viewer = $("viewer");

  // ---- State ---------------------------------------------------------------------------
  const state = {
    current: 0,                 // image shown in the image view (0 = the reference)
    errorOf: N > 1 ? 1 : 0,     // estimator whose error the error view shows
    exposure: 0,                // stops, applied to linear values before sRGB encoding
    zoom: 1,                    // device pixels per image pixel
    cx: W / 2, cy: H / 2,       // image point at the centre of the views
    fit: true,                  // refit on resize until the user zooms or pans
    showError: N > 1,
    metric: "smape",            // "smape" or "relative"
    range: 0,                   // index into RANGES
    hover: null,                // [x, y]: image pixel under the pointer, or null
  };
  const linear = new Array(N);            // Float32Array(W * H * 3) per image, once decoded
  const errorValues = new Float32Array(W * H);

  // Colour scales of the error view: logarithmic from 10^lo to 10^hi, or linear from 0 to hi.
  const RANGES = [
    { log: true, lo: -3, hi: 0 },
    { log: true, lo: -4, hi: 0 },
    { log: true, lo: -2, hi: 0 },
    { log: true, lo: -3, hi: 1 },
    { log: true, lo: -2, hi: 1 },
    { log: false, hi: 1 },
    { log: false, hi: 0.25 },
    { log: false, hi: 0.05 },
  ];
  const METRIC_NAMES = { smape: "SMAPE", relative: "relative error" };

  // ---- RGBE decoding --------------------------------------------------------------------
  // 2^(E - 136) for each exponent byte; 0 for E = 0 (black).
  const RGBE_FACTOR = new Float64Array(256);
  for (let e = 1; e < 256; e++) RGBE_FACTOR[e] = Math.pow(2, e - 136);

  function base64Bytes(text) {
    const binary = atob(text);
    const bytes = new Uint8Array(binary.length);
    for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
    return bytes;
  }

  async function decodeImage(base64) {
    const blob = new Blob([base64Bytes(base64)], { type: "image/png" });
    let bitmap;
    try {
      bitmap = await createImageBitmap(blob, { premultiplyAlpha: "none", colorSpaceConversion: "none" });
    } catch (_) {
      bitmap = await createImageBitmap(blob);    // browsers without the options
    }
    if (bitmap.width !== 2 * W || bitmap.height !== 2 * H) {
      throw new Error("an image is " + bitmap.width + "x" + bitmap.height + ", not " + 2 * W + "x" + 2 * H);
    }
    const canvas = document.createElement("canvas");
    canvas.width = 2 * W;
    canvas.height = 2 * H;
    const ctx = canvas.getContext("2d", { willReadFrequently: true });
    ctx.drawImage(bitmap, 0, 0);
    if (bitmap.close) bitmap.close();
    const grey = ctx.getImageData(0, 0, 2 * W, 2 * H).data;   // RGBA; grey in R, G and B
    const out = new Float32Array(W * H * 3);
    const right = 4 * W;          // bytes from a plane to the plane on its right
    const down = 8 * W * H;       // bytes from a plane to the plane below it
    for (let y = 0; y < H; y++) {
      for (let x = 0; x < W; x++) {
        const p = (y * 2 * W + x) * 4;
        const f = RGBE_FACTOR[grey[p + down + right]];
        const o = (y * W + x) * 3;
        out[o] = (grey[p] + 0.5) * f;
        out[o + 1] = (grey[p + right] + 0.5) * f;
        out[o + 2] = (grey[p + down] + 0.5) * f;
      }
    }
    return out;
  }

  // ---- Source canvases: the tone-mapped image and the false-colour error -----------------
  function makeCanvas(w, h) {
    const c = document.createElement("canvas");
    c.width = w;
    c.height = h;
    return c;
  }
  const shownCanvas = makeCanvas(W, H);
  const errorCanvas = makeCanvas(W, H);

  // sRGB encoding of [0, 1], tabulated finely enough that no 8-bit level is lost near black.
  const LUT_SIZE = 1 << 16;
  const SRGB = new Uint8ClampedArray(LUT_SIZE + 1);
  for (let i = 0; i <= LUT_SIZE; i++) {
    const v = i / LUT_SIZE;
    SRGB[i] = Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055));
  }

  function paintShown() {
    const values = linear[state.current];
    const ctx = shownCanvas.getContext("2d");
    const img = ctx.createImageData(W, H);
    const px = img.data;
    const scale = Math.pow(2, state.exposure) * LUT_SIZE;
    for (let p = 0, o = 0; p < W * H; p++, o += 3) {
      for (let c = 0; c < 3; c++) {
        const t = values[o + c] * scale;            // NaN and negatives fail `t > 0`: black
        px[4 * p + c] = SRGB[t > 0 ? (t < LUT_SIZE ? (t + 0.5) | 0 : LUT_SIZE) : 0];
      }
      px[4 * p + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
  }

  // Viridis, interpolated from nine samples of matplotlib's map.
  const VIRIDIS_STOPS = [
    [68, 1, 84], [71, 45, 123], [59, 82, 139], [44, 114, 142], [33, 144, 140],
    [39, 173, 129], [93, 200, 99], [170, 220, 50], [253, 231, 37],
  ];
  const VIRIDIS = new Uint8ClampedArray(256 * 3);
  for (let i = 0; i < 256; i++) {
    const t = (i / 255) * (VIRIDIS_STOPS.length - 1);
    const k = Math.min(Math.floor(t), VIRIDIS_STOPS.length - 2);
    const f = t - k;
    for (let c = 0; c < 3; c++) {
      VIRIDIS[3 * i + c] = Math.round(VIRIDIS_STOPS[k][c] * (1 - f) + VIRIDIS_STOPS[k + 1][c] * f);
    }
  }

  // Per-pixel error, mean over RGB: SMAPE |e-r|/(|e|+|r|) (a term with both zero counts 0),
  // or the relative error |e-r|/(r+0.01).
  function pixelError(e, r, o) {
    let sum = 0;
    for (let c = 0; c < 3; c++) {
      const d = Math.abs(e[o + c] - r[o + c]);
      if (state.metric === "smape") {
        const s = Math.abs(e[o + c]) + Math.abs(r[o + c]);
        if (s > 0) sum += d / s;
      } else {
        sum += d / (Math.abs(r[o + c]) + 0.01);
      }
    }
    return sum / 3;
  }

  // Position of an error value on the colour scale, 0..1.
  function scalePosition(v) {
    const r = RANGES[state.range];
    let t;
    if (r.log) t = v > 0 ? (Math.log10(v) - r.lo) / (r.hi - r.lo) : 0;
    else t = v / r.hi;
    return t > 0 ? (t < 1 ? t : 1) : 0;
  }

  function computeError() {
    const e = linear[state.errorOf], r = linear[0];
    for (let p = 0; p < W * H; p++) errorValues[p] = pixelError(e, r, 3 * p);
  }

  function paintError() {
    const ctx = errorCanvas.getContext("2d");
    const img = ctx.createImageData(W, H);
    const px = img.data;
    for (let p = 0; p < W * H; p++) {
      const i = Math.round(scalePosition(errorValues[p]) * 255) * 3;
      px[4 * p] = VIRIDIS[i];
      px[4 * p + 1] = VIRIDIS[i + 1];
      px[4 * p + 2] = VIRIDIS[i + 2];
      px[4 * p + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    paintColorbar();
  }

  function superscript(k) {
    const digits = "⁰¹²³⁴⁵⁶⁷⁸⁹";
    return (k < 0 ? "⁻" : "") + String(Math.abs(k)).split("").map((d) => digits[+d]).join("");
  }

  function paintColorbar() {
    const bar = $("colorbar");
    const ctx = bar.getContext("2d");
    const img = ctx.createImageData(256, 1);
    for (let i = 0; i < 256; i++) {
      for (let c = 0; c < 3; c++) img.data[4 * i + c] = VIRIDIS[3 * i + c];
      img.data[4 * i + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    // Tick labels: every decade on a log scale, quarters on a linear one.
    const r = RANGES[state.range];
    const ticks = $("ticks");
    ticks.textContent = "";
    const labels = [];
    if (r.log) {
      for (let k = r.lo; k <= r.hi; k++) {
        const text = k >= -2 && k <= 2 ? String(Math.pow(10, k).toFixed(Math.max(0, -k))) : "10" + superscript(k);
        labels.push([(k - r.lo) / (r.hi - r.lo), text]);
      }
    } else {
      for (let q = 0; q <= 4; q++) labels.push([q / 4, String(+(r.hi * q / 4).toPrecision(3))]);
    }
    for (const [t, text] of labels) {
      const span = document.createElement("span");
      span.style.left = (100 * t) + "%";
      span.textContent = text;
      ticks.appendChild(span);
    }
  }

  function rangeName(r) {
    if (r.log) return "log  10" + superscript(r.lo) + " … " + (r.hi === 0 ? "1" : "10" + superscript(r.hi));
    return "linear  0 … " + r.hi;
  }

  // ---- Views ---------------------------------------------------------------------------
  const views = [
    { figure: $("image-view"), source: shownCanvas },
    { figure: $("error-view"), source: errorCanvas },
  ];
  for (const v of views) {
    v.canvas = v.figure.querySelector("canvas.view-canvas");
    v.ctx = v.canvas.getContext("2d");
  }
  const visibleViews = () => views.filter((v, i) => i === 0 || state.showError);

  // Zoom levels: halvings of sqrt(2) below 1, integers from 1 up.
  const ZOOMS = [];
  for (let k = 10; k >= 1; k--) ZOOMS.push(Math.pow(2, -k / 2));
  ZOOMS.push(1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 48, 64);

  function stepZoom(z, dir) {
    if (dir > 0) return ZOOMS.find((l) => l > z * 1.0001) || ZOOMS[ZOOMS.length - 1];
    for (let i = ZOOMS.length - 1; i >= 0; i--) if (ZOOMS[i] < z * 0.9999) return ZOOMS[i];
    return ZOOMS[0];
  }

  // Device-pixel position of the image's top-left corner in a view.
  function origin(v) {
    return [
      Math.round(v.canvas.width / 2 - state.cx * state.zoom),
      Math.round(v.canvas.height / 2 - state.cy * state.zoom),
    ];
  }

  function resizeCanvases() {
    const dpr = window.devicePixelRatio || 1;
    // Make the views as high as the image at the zoom that fits their width (plus a margin),
    // within 240 px and 78 % of the window, so that little of them is empty.
    const across = views[0].canvas.getBoundingClientRect().width * dpr / W;
    const z = across >= 1 ? Math.floor(across) : across;
    const high = Math.min(Math.max(240, 0.78 * window.innerHeight), Math.max(240, (H * z) / dpr + 40));
    for (const v of views) v.canvas.style.height = Math.round(high) + "px";
    for (const v of visibleViews()) {
      const rect = v.canvas.getBoundingClientRect();
      const w = Math.max(1, Math.round(rect.width * dpr)), h = Math.max(1, Math.round(rect.height * dpr));
      if (v.canvas.width !== w || v.canvas.height !== h) {
        v.canvas.width = w;
        v.canvas.height = h;
      }
    }
    if (state.fit) fit();
  }

  function fit() {
    const c = views[0].canvas;
    const z = Math.min(c.width / W, c.height / H);
    state.zoom = z >= 1 ? Math.floor(z) : z;
    state.cx = W / 2;
    state.cy = H / 2;
    state.fit = true;
  }

  function clampCentre() {
    state.cx = Math.min(Math.max(state.cx, 0), W);
    state.cy = Math.min(Math.max(state.cy, 0), H);
  }

  function draw() {
    const z = state.zoom;
    for (const v of visibleViews()) {
      const ctx = v.ctx;
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.imageSmoothingEnabled = false;
      ctx.fillStyle = "#08090b";
      ctx.fillRect(0, 0, v.canvas.width, v.canvas.height);
      if (!linear[state.current]) continue;
      const [ox, oy] = origin(v);
      ctx.drawImage(v.source, ox, oy, W * z, H * z);
      if (state.hover) drawMarker(ctx, ox + state.hover[0] * z, oy + state.hover[1] * z, z);
    }
    $("zoom-value").textContent = state.zoom >= 1 ? state.zoom + "×" : state.zoom.toFixed(2) + "×";
  }

  // The pixel under the pointer, in both views: a square outline when zoomed in, else a cross.
  function drawMarker(ctx, x, y, z) {
    ctx.lineWidth = 1;
    if (z >= 4) {
      ctx.strokeStyle = "#000";
      ctx.strokeRect(x - 0.5, y - 0.5, z + 1, z + 1);
      ctx.strokeStyle = "#fff";
      ctx.strokeRect(x + 0.5, y + 0.5, z - 1, z - 1);
    } else {
      const cx = Math.round(x + z / 2) + 0.5, cy = Math.round(y + z / 2) + 0.5;
      ctx.strokeStyle = "#fff";
      ctx.beginPath();
      ctx.moveTo(cx - 9, cy); ctx.lineTo(cx - 3, cy);
      ctx.moveTo(cx + 3, cy); ctx.lineTo(cx + 9, cy);
      ctx.moveTo(cx, cy - 9); ctx.lineTo(cx, cy - 3);
      ctx.moveTo(cx, cy + 3); ctx.lineTo(cx, cy + 9);
      ctx.stroke();
    }
  }

  // Device-pixel position of a pointer event in a view's canvas.
  function devicePoint(v, e) {
    const rect = v.canvas.getBoundingClientRect();
    return [(e.clientX - rect.left) * (v.canvas.width / rect.width), (e.clientY - rect.top) * (v.canvas.height / rect.height)];
  }

  // Zoom one level in or out, keeping the image point at device point (mx, my) of view v.
  function zoomAbout(v, mx, my, dir) {
    const [ox, oy] = origin(v);
    const ix = (mx - ox) / state.zoom, iy = (my - oy) / state.zoom;
    state.zoom = stepZoom(state.zoom, dir);
    state.cx = ix - (mx - v.canvas.width / 2) / state.zoom;
    state.cy = iy - (my - v.canvas.height / 2) / state.zoom;
    state.fit = false;
    clampCentre();
    draw();
  }

  function zoomCentre(dir) {
    const c = views[0].canvas;
    zoomAbout(views[0], c.width / 2, c.height / 2, dir);
  }

  let drag = null;
  let wheel = 0;
  for (const v of views) {
    const c = v.canvas;
    c.addEventListener("pointerdown", (e) => {
      if (e.button !== 0) return;
      const rect = c.getBoundingClientRect();
      drag = { id: e.pointerId, x: e.clientX, y: e.clientY, cx: state.cx, cy: state.cy, ratio: c.width / rect.width };
      c.setPointerCapture(e.pointerId);
      c.classList.add("dragging");
    });
    c.addEventListener("pointermove", (e) => {
      if (drag && drag.id === e.pointerId) {
        state.cx = drag.cx - ((e.clientX - drag.x) * drag.ratio) / state.zoom;
        state.cy = drag.cy - ((e.clientY - drag.y) * drag.ratio) / state.zoom;
        state.fit = false;
        clampCentre();
      }
      setHover(v, e);
    });
    const endDrag = () => {
      drag = null;
      c.classList.remove("dragging");
    };
    c.addEventListener("pointerup", endDrag);
    c.addEventListener("pointercancel", endDrag);
    c.addEventListener("pointerleave", () => {
      if (drag) return;
      state.hover = null;
      updateReadout();
      draw();
    });
    c.addEventListener("wheel", (e) => {
      e.preventDefault();
      // One zoom step per notch; small trackpad deltas add up to one.
      wheel += e.deltaY * (e.deltaMode === 1 ? 33 : e.deltaMode === 2 ? 100 : 1);
      if (Math.abs(wheel) < 50) return;
      const [mx, my] = devicePoint(v, e);
      zoomAbout(v, mx, my, wheel < 0 ? 1 : -1);
      wheel = 0;
      setHover(v, e);
    }, { passive: false });
    c.addEventListener("dblclick", () => {
      fit();
      draw();
    });
  }

  function setHover(v, e) {
    const [mx, my] = devicePoint(v, e);
    const [ox, oy] = origin(v);
    const x = Math.floor((mx - ox) / state.zoom), y = Math.floor((my - oy) / state.zoom);
    state.hover = x >= 0 && y >= 0 && x < W && y < H ? [x, y] : null;
    updateReadout();
    draw();
  }

  // ---- Pixel readout -------------------------------------------------------------------
  function num(v) {
    if (v === 0) return "0";
    const a = Math.abs(v);
    return a >= 1e4 || a < 1e-3 ? v.toExponential(3) : v.toPrecision(4);
  }

  function span(text, cls) {
    const s = document.createElement(cls === "b" ? "b" : "span");
    if (cls && cls !== "b") s.className = cls;
    s.textContent = text;
    return s;
  }

  function rgbItem(label, values, o) {
    const item = document.createElement("span");
    const sw = span("", "swatch");
    const scale = Math.pow(2, state.exposure) * LUT_SIZE;
    const enc = (c) => SRGB[Math.max(0, Math.min(LUT_SIZE, Math.round(values[o + c] * scale))) || 0];
    sw.style.backgroundColor = "rgb(" + enc(0) + "," + enc(1) + "," + enc(2) + ")";
    item.append(sw, span(label, "b"), " " + num(values[o]) + "  " + num(values[o + 1]) + "  " + num(values[o + 2]));
    return item;
  }

  function updateReadout() {
    const out = $("readout");
    out.textContent = "";
    const marker = $("marker");
    if (!state.hover || !linear[0]) {
      marker.hidden = true;
      out.append("Point at an image to read its linear RGB values here.");
      return;
    }
    const [x, y] = state.hover;
    const p = y * W + x;
    out.append(span("x " + x + "  y " + y, "b"));
    if (state.current !== 0) out.append(rgbItem(images[state.current].label, linear[state.current], 3 * p));
    out.append(rgbItem(images[0].label, linear[0], 3 * p));
    if (N > 1) {
      const item = document.createElement("span");
      item.append(span(METRIC_NAMES[state.metric] + " of " + images[state.errorOf].label, "b"), " " + num(errorValues[p]));
      out.append(item);
      marker.hidden = !state.showError;
      marker.style.left = (100 * scalePosition(errorValues[p])) + "%";
    }
  }

  // ---- Selection, exposure, error settings ---------------------------------------------
  const buttons = Array.from(document.querySelectorAll(".choices button"));
  const rows = [];   // table rows whose first cell names an image: [row, index]
  for (const row of document.querySelectorAll("#results tr")) {
    const first = row.firstElementChild;
    if (!first || first.tagName === "TH" && first.getAttribute("scope") === "col") continue;
    const i = images.findIndex((im) => im.label === first.textContent.trim());
    if (i < 0) continue;
    row.classList.add("selectable");
    row.addEventListener("click", () => {
      select(i);
      viewer.scrollIntoView({ behavior: "smooth", block: "start" });
    });
    rows.push([row, i]);
  }

  function select(i) {
    if (!(i >= 0 && i < N) || !linear[i]) return;
    state.current = i;
    if (i > 0 && i !== state.errorOf) {
      state.errorOf = i;
      computeError();
      paintError();
    }
    paintShown();
    updateLabels();
    updateReadout();
    draw();
  }

  function updateLabels() {
    const i = state.current;
    viewer.dataset.current = String(i);
    viewer.dataset.label = images[i].label;
    viewer.dataset.error = state.showError ? "on" : "off";
    $("image-label").textContent = images[i].label;
    $("image-note").textContent = i === 0 ? "reference" : "estimator " + i + " of " + (N - 1);
    $("error-label").textContent = N > 1
      ? METRIC_NAMES[state.metric] + " of " + images[state.errorOf].label + " against " + images[0].label
      : "no estimator to compare";
    buttons.forEach((b, k) => {
      b.setAttribute("aria-pressed", String(k === i));
      b.classList.toggle("error-target", N > 1 && k === state.errorOf && state.showError);
    });
    for (const [row, k] of rows) row.classList.toggle("current", k === i);
  }

  function setExposure(ev) {
    state.exposure = Math.max(-10, Math.min(10, Math.round(ev * 4) / 4));
    $("exposure").value = String(state.exposure);
    $("exposure-value").textContent = (state.exposure >= 0 ? "+" : "−") + Math.abs(state.exposure).toFixed(2) + " EV";
    paintShown();
    updateReadout();
    draw();
  }

  function setShowError(on) {
    state.showError = on && N > 1;
    $("show-error").checked = state.showError;
    viewer.dataset.error = state.showError ? "on" : "off";
    resizeCanvases();
    updateLabels();
    updateReadout();
    draw();
  }

  function setMetric(m) {
    state.metric = m;
    $("metric").value = m;
    computeError();
    paintError();
    updateLabels();
    updateReadout();
    draw();
  }

  buttons.forEach((b, i) => b.addEventListener("click", () => select(i)));
  $("exposure").addEventListener("input", (e) => setExposure(+e.target.value));
  $("zoom-in").addEventListener("click", () => zoomCentre(1));
  $("zoom-out").addEventListener("click", () => zoomCentre(-1));
  $("fit").addEventListener("click", () => { fit(); draw(); });
  $("show-error").addEventListener("change", (e) => setShowError(e.target.checked));
  $("metric").addEventListener("change", (e) => setMetric(e.target.value));
  const rangeSelect = $("range");
  RANGES.forEach((r, i) => rangeSelect.add(new Option(rangeName(r), String(i))));
  rangeSelect.addEventListener("change", (e) => {
    state.range = +e.target.value;
    paintError();
    updateReadout();
    draw();
  });

  document.addEventListener("keydown", (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey) return;     // leave browser shortcuts alone
    const t = e.target;
    const tag = t && t.tagName;
    if (tag === "SELECT" || tag === "TEXTAREA" || (tag === "INPUT" && t.type !== "range" && t.type !== "checkbox")) return;
    if (tag === "INPUT" && t.type === "range" && e.key.startsWith("Arrow")) return;
    const k = e.key;
    if (/^[0-9]$/.test(k)) {
      select(k === "0" ? 9 : +k - 1);                // 1 = the reference, 2.. = estimators
    } else {
      switch (k) {
        case "ArrowRight": case "]": select((state.current + 1) % N); break;
        case "ArrowLeft": case "[": select((state.current + N - 1) % N); break;
        case "+": case "=": zoomCentre(1); break;
        case "-": case "_": zoomCentre(-1); break;
        case "f": case "F": fit(); draw(); break;
        case "e": setExposure(state.exposure + 0.5); break;
        case "E": setExposure(state.exposure - 0.5); break;
        case "r": case "R": setExposure(0); break;
        case "x": case "X": setShowError(!state.showError); break;
        case "m": case "M": setMetric(state.metric === "smape" ? "relative" : "smape"); break;
        default: return;
      }
    }
    e.preventDefault();
  });

  new ResizeObserver(() => {
    resizeCanvases();
    draw();
  }).observe(views[0].canvas);

  // ---- Start ---------------------------------------------------------------------------
  viewer.dataset.error = state.showError ? "on" : "off";
  const ready = Promise.all(images.map((im) => decodeImage(im.png))).then((decoded) => {
    decoded.forEach((d, i) => { linear[i] = d; });
    if (N > 1) computeError();
    paintError();
    paintShown();
    resizeCanvases();
    updateLabels();
    updateReadout();
    draw();
    viewer.dataset.ready = "true";
  }).catch((err) => {
    viewer.dataset.ready = "error";
    $("loading").textContent = "Could not decode the images: " + err.message;
    throw err;
  });

  // For scripts and tests: the state, and the decoded values.
  window.fogViewer = {
    state, ready, select, width: W, height: H, count: N,
    pixel: (i, x, y) => Array.from(linear[i].subarray(3 * (y * W + x), 3 * (y * W + x) + 3)),
    error: (x, y) => errorValues[y * W + x],
  };
})();
"##;

// ---------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random number in [0, 1).
    fn hash01(i: u64) -> f32 {
        let mut z = i.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

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

    /// The images of a page, read back as its JavaScript reads them.
    fn page_images(html: &str) -> Vec<(String, Vec<[f32; 3]>)> {
        let start = html.find("<script type=\"application/json\" id=\"fog-data\">").unwrap();
        let body = &html[start..];
        let mut out = Vec::new();
        for entry in body.split("{\"label\":").skip(1) {
            let label_end = entry.find(",\"png\":\"").unwrap();
            let label = entry[1..label_end - 1].to_string();
            let b64 = &entry[label_end + 8..];
            let b64 = &b64[..b64.find('"').unwrap()];
            let (_, _, pixels) = decode_rgbe_png(&base64_decode(b64)).unwrap();
            out.push((label, pixels));
        }
        out
    }

    fn within_rgbe(original: [f32; 3], decoded: [f32; 3]) -> bool {
        let c = original.map(|v| if v > 0.0 { v } else { 0.0 });
        let max = c[0].max(c[1]).max(c[2]);
        (0..3).all(|k| (decoded[k] - c[k]).abs() <= max / 256.0 * 1.000_01 + 3e-39)
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
        assert!(html.contains("<polyline"));
        assert!(html.contains("<kbd>1</kbd><span>reference</span>"));
        assert!(html.contains("<kbd>4</kbd><span>ours</span>"));
        assert!(!html.contains("<?xml"));
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
        i.plot_svg = Some("<svg><image href=\"https://x.test/p.png\"/></svg>");
        assert!(matches!(comparison_page(&i), Err(PageError::ExternalReference(_))));
    }

    #[test]
    fn svg_loses_prolog_and_namespaces_only() {
        let s = inline_svg(SVG);
        assert!(s.starts_with("<svg width=\"200\" height=\"100\" viewBox=\"0 0 200 100\">"), "{s}");
        assert!(s.contains("<rect x=\"0\""));
        assert_eq!(inline_svg("<svg xmlnsfoo=\"1\"/>"), "<svg xmlnsfoo=\"1\"/>");
    }

    #[test]
    fn rgbe_round_trips_within_a_256th_of_the_brightest_channel() {
        let mut values = vec![
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.5, 0.25, 0.125],
            [1e-3, 2e-5, 0.0],
            [1e-30, 1e-31, 3e-30],
            [65504.0, 1.0, 0.1],
            [1e30, 1e29, 5e30],
            [0.999_999, 0.999_999, 0.0],
            [255.0 / 256.0, 1.0 / 256.0, 0.0],
        ];
        for i in 0..20_000u64 {
            let e = (hash01(4 * i) * 40.0 - 20.0).exp2();
            values.push([hash01(4 * i + 1) * e, hash01(4 * i + 2) * e, hash01(4 * i + 3) * e]);
        }
        for v in values {
            let d = rgbe_decode(rgbe_encode(v));
            assert!(within_rgbe(v, d), "{v:?} -> {d:?}");
        }
        // Out of range: negatives and NaN are black, +inf is the largest value, tiny is black.
        assert_eq!(rgbe_decode(rgbe_encode([-1.0, f32::NAN, 0.5])), rgbe_decode(rgbe_encode([0.0, 0.0, 0.5])));
        assert!(rgbe_decode(rgbe_encode([f32::INFINITY, 0.0, 0.0]))[0] > 1e38);
        assert_eq!(rgbe_encode([1e-39, 0.0, 0.0]), [0; 4]);
        assert_eq!(rgbe_encode([1.0, 0.5, 0.0]), [128, 64, 0, 129]);
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
            assert_eq!(
                label.replace("\\u003c", "<").replace("\\u003e", ">").replace("\\u0026", "&").replace("\\\"", "\""),
                s.labels[k]
            );
            assert_eq!(pixels.len(), (w * h) as usize);
            for (o, d) in s.pixels[k].iter().zip(pixels) {
                assert!(within_rgbe(*o, *d), "{o:?} -> {d:?}");
            }
        }
    }

    #[test]
    fn base64_matches_known_vectors() {
        for (raw, enc) in [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foobar", "Zm9vYmFy")] {
            let mut s = String::new();
            base64_into(raw.as_bytes(), &mut s);
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
    }
}
