//! The scene as a Mitsuba 3 XML file, for checking the renderers against an outside one.
//!
//! The file renders what fogplanes renders, direct emission plus single scattering, with
//! Mitsuba's `volpath` integrator: `max_depth` 2 (one medium or surface interaction; crossing
//! the box's `null` boundary does not count) and no Russian roulette.
//!
//! The mapping, object by object:
//!
//! - The medium box is a `cube` (which spans `[-1, 1]^3`) scaled and moved onto the box (a face
//!   in whose plane a light lies is moved out by a thin shell, see [`mitsuba_box`]), with a
//!   `null` BSDF and the `homogeneous` medium inside it: `sigma_t` per channel, given as a
//!   `constvolume` because Mitsuba refuses plain RGB values above 1 for it, `albedo` =
//!   sigma_s / sigma_t (0 where sigma_t is 0), an `isotropic` phase function, or `hg` with the
//!   scene's `g` (the same sign convention: positive scatters forward).
//! - Each light is a `rectangle` (which spans `[-1, 1]^2` in its local xy plane, normal +z)
//!   whose `to_world` has the columns `edge_u / 2`, `edge_v / 2`, `n` and the centre
//!   `corner + (edge_u + edge_v) / 2`, so that local `(-1, -1)`, `(1, -1)`, `(-1, 1)` are the
//!   corner, corner + edge_u and corner + edge_v, and +z is the front. It has an `area` emitter
//!   of the light's radiance (one-sided, front face, like fogplanes) and a black `diffuse` BSDF:
//!   an opaque panel whose back is black. The fog is both its exterior medium (the front side)
//!   and its interior one (Mitsuba's name for the back side of an open surface): both sides of
//!   the panel are in the fog. With the black BSDF `volpath` never continues a path through a
//!   panel, so the image does not depend on these two references; they only keep the file
//!   truthful should the BSDF change.
//! - The camera is a `perspective` sensor with `fov_axis` "y", the vertical field of view, the
//!   look-at frame `(position, position + forward, up)` and a `box` pixel filter, so that a
//!   pixel is the average over its square, as in fogplanes' renders (whole pixels). Its film
//!   column 0 is on the left (-right) and row 0 at the top, as in fogplanes: no mirroring is
//!   needed (checked numerically by `tests/mitsuba/check_export.py`). A camera inside the box
//!   (or on its boundary) gets the fog as its medium.
//!
//! Mitsuba renders in single precision and moves every ray leaving a surface by
//! `(1 + max |p_i|) * 9e-5`: in scenes much smaller than one unit that offset is a visible part
//! of the box (`media_scenes/hard/scaled_1e-3.toml` comes out 2% too bright), so the check is
//! meant for scenes of ordinary size. It moves camera rays too, where they enter the box: on the
//! benchmark all by the same 5.4e-4 along the front face's normal, as if Mitsuba's camera stood
//! that much nearer, which shifts the lights' outlines by up to 0.017 pixel (0.008 for the red
//! spot; docs/mitsuba_red_spot.md). The file keeps the scene's camera: the offset depends on
//! where each ray crosses, which the export does not know.
//!
//! The resolution, samples per pixel and seed are Mitsuba `<default>` parameters (`resx`,
//! `resy`, `spp`, `seed`) that `mitsuba -D` or `mi.load_file(path, spp=...)` override.

use crate::scene::Scene;
use glam::{DMat4, DVec3};
use std::fmt::Write;

/// Samples per pixel written as the file's default (`spp` overrides it).
pub const DEFAULT_SPP: u32 = 256;

/// The Mitsuba 3 XML text of the scene (see the module documentation for the mapping).
pub fn mitsuba_xml(scene: &Scene) -> String {
    let mut x = String::new();
    let cam = &scene.camera;
    let m = &scene.medium;
    let diagonal = m.diagonal();

    let _ = writeln!(x, r#"<?xml version="1.0" encoding="utf-8"?>"#);
    let _ = writeln!(
        x,
        "<!-- Exported by fogplanes from the scene \"{}\": direct emission plus single scattering\n     \
         in a homogeneous fog box. Render with the scalar_rgb variant, e.g.\n     \
         mitsuba -m scalar_rgb -D spp=1024 -D resx=64 -D resy=36 FILE.xml -->",
        comment_text(&scene.name)
    );
    let _ = writeln!(x, r#"<scene version="3.0.0">"#);
    let _ = writeln!(x, r#"    <default name="resx" value="{}"/>"#, cam.width);
    let _ = writeln!(x, r#"    <default name="resy" value="{}"/>"#, cam.height);
    let _ = writeln!(x, r#"    <default name="spp" value="{DEFAULT_SPP}"/>"#);
    let _ = writeln!(x, r#"    <default name="seed" value="0"/>"#);
    let _ = writeln!(x);

    // Single scattering: depth 1 is the emission seen directly, depth 2 one interaction.
    let _ = writeln!(x, r#"    <integrator type="volpath">"#);
    let _ = writeln!(x, r#"        <integer name="max_depth" value="2"/>"#);
    let _ = writeln!(x, r#"        <integer name="rr_depth" value="1000000"/>"#);
    let _ = writeln!(x, r#"        <boolean name="hide_emitters" value="false"/>"#);
    let _ = writeln!(x, r#"    </integrator>"#);
    let _ = writeln!(x);

    let _ = writeln!(x, r#"    <medium type="homogeneous" id="fog">"#);
    let sigma_t = m.sigma_t();
    let albedo = DVec3::select(sigma_t.cmpgt(DVec3::ZERO), m.sigma_s / sigma_t, DVec3::ZERO);
    let _ = writeln!(x, r#"        <volume type="constvolume" name="sigma_t">"#);
    let _ = writeln!(x, r#"            <rgb name="value" value="{}"/>"#, triple(sigma_t));
    let _ = writeln!(x, r#"        </volume>"#);
    let _ = writeln!(x, r#"        <rgb name="albedo" value="{}"/>"#, triple(albedo));
    // Mitsuba's `hg` has fogplanes' sign convention (positive g scatters forward), section 1.1.
    if m.g == 0.0 {
        let _ = writeln!(x, r#"        <phase type="isotropic"/>"#);
    } else {
        let _ = writeln!(x, r#"        <phase type="hg">"#);
        let _ = writeln!(x, r#"            <float name="g" value="{}"/>"#, num(m.g));
        let _ = writeln!(x, r#"        </phase>"#);
    }
    let _ = writeln!(x, r#"    </medium>"#);
    let _ = writeln!(x);

    let _ = writeln!(x, r#"    <sensor type="perspective">"#);
    let _ = writeln!(x, r#"        <string name="fov_axis" value="y"/>"#);
    let vfov = 2.0 * cam.tan_half_fov.atan().to_degrees();
    let _ = writeln!(x, r#"        <float name="fov" value="{}"/>"#, num(vfov));
    // Mitsuba starts camera rays at the near clip plane: from a camera inside the fog the
    // segment before it is lost (at sigma_t = 50 the default 0.01 brightens the image by 5%),
    // so it is a ten-millionth of the box diagonal (directions stay exact to 1e-7 in single
    // precision). The far plane lies beyond the farthest corner of the box.
    let farthest = (m.min - cam.position).abs().max((m.max - cam.position).abs()).length();
    let _ = writeln!(x, r#"        <float name="near_clip" value="{}"/>"#, num(1e-7 * diagonal));
    let _ = writeln!(x, r#"        <float name="far_clip" value="{}"/>"#, num(4.0 * (farthest + diagonal)));
    let _ = writeln!(x, r#"        <transform name="to_world">"#);
    let _ = writeln!(
        x,
        r#"            <lookat origin="{}" target="{}" up="{}"/>"#,
        triple(cam.position),
        triple(cam.position + cam.forward),
        triple(cam.up)
    );
    let _ = writeln!(x, r#"        </transform>"#);
    if m.contains(cam.position, 0.0) {
        let _ = writeln!(x, r#"        <ref id="fog" name="medium"/>"#);
    }
    let _ = writeln!(x, r#"        <sampler type="independent">"#);
    let _ = writeln!(x, r#"            <integer name="sample_count" value="$spp"/>"#);
    let _ = writeln!(x, r#"            <integer name="seed" value="$seed"/>"#);
    let _ = writeln!(x, r#"        </sampler>"#);
    let _ = writeln!(x, r#"        <film type="hdrfilm">"#);
    let _ = writeln!(x, r#"            <integer name="width" value="$resx"/>"#);
    let _ = writeln!(x, r#"            <integer name="height" value="$resy"/>"#);
    let _ = writeln!(x, r#"            <string name="pixel_format" value="rgb"/>"#);
    let _ = writeln!(x, r#"            <rfilter type="box"/>"#);
    let _ = writeln!(x, r#"        </film>"#);
    let _ = writeln!(x, r#"    </sensor>"#);
    let _ = writeln!(x);

    let _ = writeln!(x, r#"    <shape type="cube" id="fog_box">"#);
    let _ = writeln!(x, r#"        <transform name="to_world">"#);
    let _ = writeln!(x, r#"            <matrix value="{}"/>"#, matrix(&box_to_world(scene)));
    let _ = writeln!(x, r#"        </transform>"#);
    let _ = writeln!(x, r#"        <bsdf type="null"/>"#);
    let _ = writeln!(x, r#"        <ref id="fog" name="interior"/>"#);
    let _ = writeln!(x, r#"    </shape>"#);

    for (i, light) in scene.lights.iter().enumerate() {
        let _ = writeln!(x);
        let _ = writeln!(x, r#"    <shape type="rectangle" id="{}">"#, light_id(i, &light.name));
        let _ = writeln!(x, r#"        <transform name="to_world">"#);
        let _ = writeln!(x, r#"            <matrix value="{}"/>"#, matrix(&rectangle_to_world(light)));
        let _ = writeln!(x, r#"        </transform>"#);
        let _ = writeln!(x, r#"        <bsdf type="diffuse">"#);
        let _ = writeln!(x, r#"            <rgb name="reflectance" value="0, 0, 0"/>"#);
        let _ = writeln!(x, r#"        </bsdf>"#);
        let _ = writeln!(x, r#"        <emitter type="area">"#);
        let _ = writeln!(x, r#"            <rgb name="radiance" value="{}"/>"#, triple(light.radiance));
        let _ = writeln!(x, r#"        </emitter>"#);
        let _ = writeln!(x, r#"        <ref id="fog" name="exterior"/>"#);
        let _ = writeln!(x, r#"        <ref id="fog" name="interior"/>"#);
        let _ = writeln!(x, r#"    </shape>"#);
    }
    let _ = writeln!(x, "</scene>");
    x
}

/// How far Mitsuba (single precision) moves the origin of a ray leaving a surface point whose
/// largest coordinate magnitude is `max_abs`: `(1 + max_abs) * 1500 * 2^-24`, along the normal.
pub fn mitsuba_ray_offset(max_abs: f64) -> f64 {
    (1.0 + max_abs) * 1500.0 * (-24f64).exp2()
}

/// The box given to Mitsuba as `(min, max)`: the medium box, except that a face in whose plane
/// a light lies (all its corners within the shell below) is moved outward by a thin shell.
///
/// A light lying in a face is coplanar with the cube, and Mitsuba then meets the cube's null
/// face or the light in no set order: a ray that meets the face first leaves the fog and passes
/// the light (the benchmark's hard scene `light_on_box_face` renders 32% too dark). The shell
/// is the larger of 1e-4 of the box diagonal and twice Mitsuba's ray offset at the box, so
/// that a ray entering through the moved face still starts before the light's back. The fog in
/// it changes the image by about sigma_t times its thickness; other faces stay exact.
pub fn mitsuba_box(scene: &Scene) -> (DVec3, DVec3) {
    let m = &scene.medium;
    let shell = (1e-4 * m.diagonal()).max(2.0 * mitsuba_ray_offset(m.min.abs().max(m.max.abs()).max_element()));
    let (mut lo, mut hi) = (m.min, m.max);
    for axis in 0..3 {
        let in_plane =
            |plane: f64| scene.lights.iter().any(|l| l.corners().iter().all(|c| (c[axis] - plane).abs() <= shell));
        if in_plane(m.min[axis]) {
            lo[axis] -= shell;
        }
        if in_plane(m.max[axis]) {
            hi[axis] += shell;
        }
    }
    (lo, hi)
}

/// The affine map from Mitsuba's cube `[-1, 1]^3` onto [`mitsuba_box`].
pub fn box_to_world(scene: &Scene) -> DMat4 {
    let (min, max) = mitsuba_box(scene);
    let half = 0.5 * (max - min);
    let centre = 0.5 * (min + max);
    DMat4::from_cols(
        (DVec3::X * half.x).extend(0.0),
        (DVec3::Y * half.y).extend(0.0),
        (DVec3::Z * half.z).extend(0.0),
        centre.extend(1.0),
    )
}

/// The affine map from Mitsuba's rectangle (`[-1, 1]^2` at z = 0, normal +z) onto the light:
/// columns `edge_u / 2`, `edge_v / 2`, the unit normal and the centre.
pub fn rectangle_to_world(light: &crate::light::RectLight) -> DMat4 {
    let half_u = 0.5 * light.width * light.u;
    let half_v = 0.5 * light.height * light.v;
    DMat4::from_cols(
        half_u.extend(0.0),
        half_v.extend(0.0),
        light.n.extend(0.0),
        (light.corner + half_u + half_v).extend(1.0),
    )
}

/// A number that reads back as the same f64 (Rust's shortest round-trip form).
fn num(v: f64) -> String {
    // `{:?}` prints "1e-7" or "0.1"; both are valid XML attribute text and C `strtod` input.
    // Negative zero is written as 0 (no sign games in an outside parser).
    if v == 0.0 { "0".to_string() } else { format!("{v:?}") }
}

fn triple(v: DVec3) -> String {
    format!("{}, {}, {}", num(v.x), num(v.y), num(v.z))
}

/// The 16 entries of a 4x4 matrix, row by row (Mitsuba's `<matrix value=...>` order).
fn matrix(m: &DMat4) -> String {
    let rows = (0..4).map(|r| {
        let row = m.row(r);
        format!("{} {} {} {}", num(row.x), num(row.y), num(row.z), num(row.w))
    });
    rows.collect::<Vec<_>>().join("  ")
}

/// A unique, XML- and Mitsuba-safe id: `light<index>_<name with only [A-Za-z0-9_]>`.
fn light_id(index: usize, name: &str) -> String {
    let clean: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
    format!("light{index}_{clean}")
}

/// Text safe inside an XML comment (no "--", no markup characters).
fn comment_text(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() || "_. ".contains(c) { c } else { '_' }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec4;

    /// A minimal XML element tree: enough to check well-formedness and read values back.
    #[derive(Debug)]
    struct Element {
        name: String,
        attrs: Vec<(String, String)>,
        children: Vec<Element>,
    }

    impl Element {
        fn attr(&self, key: &str) -> Option<&str> {
            self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
        }
        fn find_all<'a>(&'a self, pred: &dyn Fn(&Element) -> bool, out: &mut Vec<&'a Element>) {
            if pred(self) {
                out.push(self);
            }
            for c in &self.children {
                c.find_all(pred, out);
            }
        }
        fn child(&self, name: &str, attr_name: Option<&str>) -> &Element {
            self.children
                .iter()
                .find(|c| c.name == name && attr_name.is_none_or(|n| c.attr("name") == Some(n)))
                .unwrap_or_else(|| panic!("<{}> has no <{name} name={attr_name:?}>", self.name))
        }
    }

    fn is_name_char(c: char) -> bool {
        c.is_ascii_alphanumeric() || "_-.:".contains(c)
    }

    /// Parses the document strictly: one root, properly nested tags, quoted attributes without
    /// raw `<` or `&`, no text content other than whitespace. Panics with the reason otherwise.
    fn parse_xml(text: &str) -> Element {
        let mut rest = text.trim_start();
        if let Some(r) = rest.strip_prefix("<?xml") {
            let end = r.find("?>").expect("unterminated XML declaration");
            rest = &r[end + 2..];
        }
        let mut stack: Vec<Element> = Vec::new();
        let mut root = None;
        loop {
            rest = rest.trim_start();
            if rest.is_empty() {
                break;
            }
            assert!(rest.starts_with('<'), "text outside tags: {:?}", &rest[..rest.len().min(40)]);
            if let Some(r) = rest.strip_prefix("<!--") {
                let end = r.find("-->").expect("unterminated comment");
                assert!(!r[..end].contains("--"), "\"--\" inside a comment");
                rest = &r[end + 3..];
                continue;
            }
            if let Some(r) = rest.strip_prefix("</") {
                let end = r.find('>').expect("unterminated closing tag");
                let name = r[..end].trim();
                let open = stack.pop().unwrap_or_else(|| panic!("</{name}> closes nothing"));
                assert_eq!(open.name, name, "</{name}> closes <{}>", open.name);
                rest = &r[end + 1..];
                match stack.last_mut() {
                    Some(parent) => parent.children.push(open),
                    None => {
                        assert!(root.is_none(), "two root elements");
                        root = Some(open);
                    }
                }
                continue;
            }
            let mut r = &rest[1..];
            let name_len = r.find(|c: char| !is_name_char(c)).unwrap_or(r.len());
            assert!(name_len > 0, "empty tag name");
            let mut el = Element { name: r[..name_len].to_string(), attrs: Vec::new(), children: Vec::new() };
            r = &r[name_len..];
            let self_closing;
            loop {
                let t = r.trim_start();
                assert!(t.len() < r.len() || t.starts_with('>') || t.starts_with("/>"), "attributes need spaces");
                r = t;
                if let Some(t) = r.strip_prefix("/>") {
                    self_closing = true;
                    r = t;
                    break;
                }
                if let Some(t) = r.strip_prefix('>') {
                    self_closing = false;
                    r = t;
                    break;
                }
                let key_len = r.find(|c: char| !is_name_char(c)).unwrap_or(r.len());
                assert!(key_len > 0, "bad attribute in <{}>: {:?}", el.name, &r[..r.len().min(30)]);
                let key = r[..key_len].to_string();
                let t = r[key_len..].strip_prefix("=\"").unwrap_or_else(|| panic!("{key} needs =\"...\""));
                let end = t.find('"').expect("unterminated attribute value");
                let value = &t[..end];
                assert!(!value.contains('<') && !value.contains('&'), "raw markup in {key}={value:?}");
                assert!(el.attr(&key).is_none(), "duplicate attribute {key}");
                el.attrs.push((key, value.to_string()));
                r = &t[end + 1..];
            }
            rest = r;
            if self_closing {
                match stack.last_mut() {
                    Some(parent) => parent.children.push(el),
                    None => {
                        assert!(root.is_none(), "two root elements");
                        root = Some(el);
                    }
                }
            } else {
                stack.push(el);
            }
        }
        assert!(stack.is_empty(), "unclosed <{}>", stack.last().unwrap().name);
        root.expect("no root element")
    }

    fn numbers(s: &str) -> Vec<f64> {
        s.split([',', ' ']).filter(|t| !t.is_empty()).map(|t| t.parse::<f64>().expect("a number")).collect()
    }

    fn vec3(s: &str) -> DVec3 {
        let v = numbers(s);
        assert_eq!(v.len(), 3, "{s}");
        DVec3::new(v[0], v[1], v[2])
    }

    fn matrix_of(shape: &Element) -> DMat4 {
        let v = numbers(shape.child("transform", Some("to_world")).child("matrix", None).attr("value").unwrap());
        assert_eq!(v.len(), 16);
        DMat4::from_cols_array(&v.try_into().unwrap()).transpose()
    }

    fn shapes<'a>(root: &'a Element, kind: &str) -> Vec<&'a Element> {
        let mut out = Vec::new();
        root.find_all(&|e| e.name == "shape" && e.attr("type") == Some(kind), &mut out);
        out
    }

    fn benchmark() -> Scene {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../media_scenes/six_lights.toml");
        Scene::load(std::path::Path::new(path)).unwrap()
    }

    /// A scene with awkward names, coloured fog and the camera inside the box.
    fn awkward() -> Scene {
        let text = r#"
[camera]
position = [0.1, 1.0, 1.5]
look_at = [0.3, 0.9, -1.0]
up = [0.0, 1.0, 0.1]
vfov_deg = 33.3
resolution = [48, 20]

[medium]
min = [-2.0, 0.0, -2.0]
max = [2.0, 2.0, 2.0]
sigma_s = [0.1, 0.0, 2.3]
sigma_a = [0.05, 0.0, 0.7]
g = -0.7

[[light]]
name = "a <\"b\"> & c -- d"
corner = [-0.5, 1.9, -0.5]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.7]
radiance = [4, 0.1, 1e-7]

[[light]]
name = "a <\"b\"> & c -- d"
corner = [1.0, 0.2, -1.0]
edge_u = [0.0, 0.3, 0.3]
edge_v = [-0.2, 0.2, -0.2]
radiance = 2.5
"#;
        Scene::parse(text, "awkward.toml", "odd -- name").unwrap()
    }

    #[test]
    fn the_xml_is_well_formed_with_unique_ids() {
        for scene in [benchmark(), awkward()] {
            let xml = mitsuba_xml(&scene);
            let root = parse_xml(&xml);
            assert_eq!(root.name, "scene");
            assert_eq!(shapes(&root, "rectangle").len(), scene.lights.len());
            assert_eq!(shapes(&root, "cube").len(), 1);
            // Every id is defined once, and every reference names a defined id.
            let (mut defs, mut refs) = (Vec::new(), Vec::new());
            root.find_all(&|e| e.name != "ref" && e.attr("id").is_some(), &mut defs);
            root.find_all(&|e| e.name == "ref", &mut refs);
            let mut ids: Vec<&str> = defs.iter().map(|e| e.attr("id").unwrap()).collect();
            let n = ids.len();
            ids.sort();
            ids.dedup();
            assert_eq!(ids.len(), n, "duplicate ids: {ids:?}");
            assert!(!refs.is_empty());
            assert!(refs.iter().all(|r| ids.contains(&r.attr("id").unwrap())));
        }
    }

    #[test]
    fn rectangles_map_onto_the_lights() {
        for scene in [benchmark(), awkward()] {
            let root = parse_xml(&mitsuba_xml(&scene));
            for (light, shape) in scene.lights.iter().zip(shapes(&root, "rectangle")) {
                let m = matrix_of(shape);
                let at = |x: f64, y: f64| m.transform_point3(DVec3::new(x, y, 0.0));
                let [c0, c1, c2, c3] = light.corners();
                let tol = 1e-12 * (1.0 + light.corner.length() + light.width + light.height);
                for (got, want) in [(at(-1.0, -1.0), c0), (at(1.0, -1.0), c1), (at(1.0, 1.0), c2), (at(-1.0, 1.0), c3)]
                {
                    assert!((got - want).length() <= tol, "{}: {got} vs {want}", light.name);
                }
                // +z is the front: as a direction and as a normal (inverse transpose).
                assert!((m.transform_vector3(DVec3::Z) - light.n).length() < 1e-12);
                let normal = m.inverse().transpose().transform_vector3(DVec3::Z).normalize();
                assert!((normal - light.n).length() < 1e-9, "{}: {normal} vs {}", light.name, light.n);
                let radiance = shape.child("emitter", None).child("rgb", Some("radiance")).attr("value").unwrap();
                assert_eq!(vec3(radiance), light.radiance);
                let media: Vec<_> = shape.children.iter().filter(|c| c.name == "ref").collect();
                assert_eq!(media.len(), 2);
                assert!(media.iter().all(|r| r.attr("id") == Some("fog")));
            }
        }
    }

    #[test]
    fn the_box_medium_and_camera_round_trip() {
        for scene in [benchmark(), awkward()] {
            let root = parse_xml(&mitsuba_xml(&scene));
            let cube = shapes(&root, "cube")[0];
            let m = matrix_of(cube);
            let med = &scene.medium;
            assert_eq!(m.transform_point3(DVec3::splat(-1.0)), med.min);
            assert_eq!(m.transform_point3(DVec3::splat(1.0)), med.max);
            assert_eq!(cube.child("bsdf", None).attr("type"), Some("null"));
            assert_eq!(cube.child("ref", Some("interior")).attr("id"), Some("fog"));

            let medium = root.child("medium", None);
            assert_eq!(medium.attr("type"), Some("homogeneous"));
            let sigma_t =
                vec3(medium.child("volume", Some("sigma_t")).child("rgb", Some("value")).attr("value").unwrap());
            let albedo = vec3(medium.child("rgb", Some("albedo")).attr("value").unwrap());
            assert_eq!(sigma_t, med.sigma_t());
            for c in 0..3 {
                let want = if med.sigma_t()[c] > 0.0 { med.sigma_s[c] / med.sigma_t()[c] } else { 0.0 };
                assert_eq!(albedo[c], want);
                assert!((0.0..=1.0).contains(&albedo[c]));
            }
            let phase = medium.child("phase", None);
            if med.g == 0.0 {
                assert_eq!(phase.attr("type"), Some("isotropic"));
            } else {
                assert_eq!(phase.attr("type"), Some("hg"));
                let g: f64 = phase.child("float", Some("g")).attr("value").unwrap().parse().unwrap();
                assert_eq!(g, med.g);
            }

            let integrator = root.child("integrator", None);
            assert_eq!(integrator.attr("type"), Some("volpath"));
            assert_eq!(integrator.child("integer", Some("max_depth")).attr("value"), Some("2"));

            let cam = &scene.camera;
            let sensor = root.child("sensor", None);
            assert_eq!(sensor.child("string", Some("fov_axis")).attr("value"), Some("y"));
            let fov: f64 = sensor.child("float", Some("fov")).attr("value").unwrap().parse().unwrap();
            assert!(((0.5 * fov).to_radians().tan() - cam.tan_half_fov).abs() < 1e-14);
            let lookat = sensor.child("transform", Some("to_world")).child("lookat", None);
            let (origin, target, up) = (
                vec3(lookat.attr("origin").unwrap()),
                vec3(lookat.attr("target").unwrap()),
                vec3(lookat.attr("up").unwrap()),
            );
            assert_eq!(origin, cam.position);
            assert!(((target - origin).normalize() - cam.forward).length() < 1e-15);
            assert_eq!(up, cam.up);
            let film = sensor.child("film", None);
            assert_eq!(film.child("rfilter", None).attr("type"), Some("box"));
            let default = |name: &str| {
                root.children
                    .iter()
                    .find(|c| c.name == "default" && c.attr("name") == Some(name))
                    .unwrap()
                    .attr("value")
            };
            assert_eq!(default("resx"), Some(cam.width.to_string().as_str()));
            assert_eq!(default("resy"), Some(cam.height.to_string().as_str()));
            let inside = med.contains(cam.position, 0.0);
            assert_eq!(sensor.children.iter().any(|c| c.name == "ref" && c.attr("id") == Some("fog")), inside);
        }
        assert!(!benchmark().medium.contains(benchmark().camera.position, 0.0));
        assert!(awkward().medium.contains(awkward().camera.position, 0.0));
    }

    #[test]
    fn faces_holding_a_light_move_out_by_a_shell_and_no_others() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../media_scenes/hard/light_on_box_face.toml");
        let scene = Scene::load(std::path::Path::new(path)).unwrap();
        let m = &scene.medium;
        let (lo, hi) = mitsuba_box(&scene);
        // The lights lie in the top face (y = max) and the back face (z = min).
        assert_eq!((lo.x, lo.y, hi.x, hi.z), (m.min.x, m.min.y, m.max.x, m.max.z));
        let (top, back) = (hi.y - m.max.y, m.min.z - lo.z);
        let offset = mitsuba_ray_offset(m.min.abs().max(m.max.abs()).max_element());
        for shell in [top, back] {
            assert!(shell >= 2.0 * offset && shell >= 1e-4 * m.diagonal() && shell < 1e-3 * m.diagonal(), "{shell}");
        }
        let root = parse_xml(&mitsuba_xml(&scene));
        let cube = matrix_of(shapes(&root, "cube")[0]);
        assert!((cube.transform_point3(DVec3::splat(-1.0)) - lo).length() < 1e-12);
        assert!((cube.transform_point3(DVec3::splat(1.0)) - hi).length() < 1e-12);
        // The benchmark's lights lie inside: its box is exact.
        let b = benchmark();
        assert_eq!(mitsuba_box(&b), (b.medium.min, b.medium.max));
    }

    #[test]
    fn numbers_round_trip_exactly() {
        for v in [
            0.1,
            1.0 / 3.0,
            -2.5e-300,
            6.02e23,
            f64::MIN_POSITIVE,
            -0.0,
            0.0,
            1e-7,
            123_456_789.123_456_79,
            0.7999999999999999,
        ] {
            assert_eq!(num(v).parse::<f64>().unwrap(), v);
        }
        assert_eq!(num(-0.0), "0");
        let m = DMat4::from_cols(
            DVec4::new(0.1, 0.2, 0.3, 0.0),
            DVec4::new(1.0 / 3.0, 2.0, 3.0, 0.0),
            DVec4::new(4.0, 5.0, 6.0, 0.0),
            DVec4::new(7.0, 8.0, 9.0, 1.0),
        );
        let v = numbers(&matrix(&m));
        assert_eq!(DMat4::from_cols_array(&v.try_into().unwrap()).transpose(), m);
    }
}
