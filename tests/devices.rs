//! Hostile inputs V: every output says which devices made it, refusals come before any driver,
//! and a GPU render's stderr holds fogplanes' lines alone. Each test failed before its mend
//! (the test's comment says how).
//!
//! The GPU's tests run on lavapipe (Mesa's Vulkan on the CPU) where there is no GPU; without
//! any Vulkan adapter they say SKIPPED, unless `FOGPLANES_REQUIRE_GPU=1`.

use crate::common::fogplanes;
use crate::gpu::have_gpu;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const SCENE: &str = "media_scenes/six_lights.toml";

/// A fresh directory for `test`.
fn dir(test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fogplanes-devices-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The command line with `args`, in the crate's root, with `env` set and `unset` removed.
fn run_with(args: &[&str], env: &[(&str, &str)], unset: &[&str]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fogplanes"));
    c.args(args).current_dir(env!("CARGO_MANIFEST_DIR"));
    for (k, v) in env {
        c.env(k, v);
    }
    for k in unset {
        c.env_remove(k);
    }
    c.output().unwrap()
}

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// The variables of gpu/mod.rs `Tuning`, the choices fixed for measuring on a device.
const TUNING: [&str; 8] = [
    "FOGPLANES_GPU_MATH",
    "FOGPLANES_GPU_CHECKS",
    "FOGPLANES_GPU_ITEM_PLANES",
    "FOGPLANES_GPU_ORIENTATIONS",
    "FOGPLANES_GPU_PIECES",
    "FOGPLANES_GPU_BINNING",
    "FOGPLANES_GPU_K",
    "FOGPLANES_GPU_LANES",
];

/// A GPU render of the scene to `d/name.exr` with `args`, the tuning variables of `env` set and
/// the others removed (their defaults, whatever this process was given): its pixels and what it
/// printed.
fn tuned_render(d: &Path, name: &str, args: &[&str], env: &[(&str, &str)]) -> (Vec<glam::Vec3>, String) {
    let (pixels, printed, _) = tuned_run(d, name, args, env);
    (pixels, printed)
}

/// [`tuned_render`] with what it wrote on stderr too; the trace (`FOGPLANES_TRACE`) is off
/// unless `env` sets it.
fn tuned_run(d: &Path, name: &str, args: &[&str], env: &[(&str, &str)]) -> (Vec<glam::Vec3>, String, String) {
    let out = d.join(format!("{name}.exr"));
    let mut all = vec!["render", SCENE, "--device", "gpu"];
    all.extend(args);
    all.extend(["-o", path(&out)]);
    let unset: Vec<&str> =
        TUNING.into_iter().chain(["FOGPLANES_TRACE"]).filter(|v| !env.iter().any(|(k, _)| k == v)).collect();
    let o = run_with(&all, env, &unset);
    let (printed, err) = text(&o);
    assert!(o.status.success(), "{name}: {err}");
    (fogplanes::film::Film::load_exr(&out).unwrap().pixels, printed, err)
}

/// What `fogplanes info` prints of `image`'s devices.
fn devices_of(image: &Path) -> String {
    let o = fogplanes(&["info", path(image)]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    out.lines().find_map(|l| l.strip_prefix("devices: ")).unwrap_or_else(|| panic!("no devices: {out}")).to_string()
}

/// A render's image and its part files record the device that gathered; a merge of parts
/// gathered on the CPU and on the GPU records both (it recorded `device: cpu`, its settings
/// remade without the device).
#[test]
fn a_merge_of_cpu_and_gpu_parts_records_both_devices() {
    if !have_gpu("a_merge_of_cpu_and_gpu_parts_records_both_devices") {
        return;
    }
    let d = dir("merge");
    let common = ["render", SCENE, "--resolution", "16x9", "--planes", "16400", "-q"];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = common.iter().chain(extra).copied().collect();
        let o = fogplanes(&args);
        assert!(o.status.success(), "{args:?}: {}", text(&o).1);
    };
    let (a, b, merged, whole) = (d.join("a.npz"), d.join("b.npz"), d.join("merged.exr"), d.join("cpu.exr"));
    run(&["-o", path(&whole)]);
    assert_eq!(devices_of(&whole), "cpu");
    run(&["--plane-range", "0:16384", "--partial", path(&a)]);
    run(&["--plane-range", "16384:16400", "--partial", path(&b), "--device", "gpu"]);
    let part = fogplanes::partial::parts::read_part(&b).unwrap();
    let recorded = part.meta.render.unwrap().devices;
    assert!(recorded.len() == 1 && recorded[0].starts_with("gpu: "), "{recorded:?}");
    let o = fogplanes(&["merge", path(&a), path(&b), "-o", path(&merged)]);
    assert!(o.status.success(), "{}", text(&o).1);
    let devices = devices_of(&merged);
    assert!(devices.starts_with("cpu; gpu: ") && devices == format!("cpu; {}", recorded[0]), "{devices}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A render checkpointed on the GPU and resumed on the CPU goes on, and says so: the resume line
/// and the summary name the GPU, and the image records both devices (it named the CPU alone,
/// and said nothing).
#[test]
fn a_checkpoint_begun_on_the_gpu_and_resumed_on_the_cpu_says_so() {
    use fogplanes::control::Control;
    use fogplanes::settings::Overrides;
    if !have_gpu("a_checkpoint_begun_on_the_gpu_and_resumed_on_the_cpu_says_so") {
        return;
    }
    let d = dir("resume");
    let ck = d.join("ck");
    std::fs::create_dir_all(&ck).unwrap();
    // What a GPU render of 16,400 planes leaves in its checkpoint after its first chunk.
    let scene = fogplanes::scene::Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join(SCENE)).unwrap();
    let given = Overrides {
        planes: Some(16_400),
        resolution: Some((16, 9)),
        device: Some(fogplanes::gpu::Device::GPU),
        ..Overrides::default()
    };
    let r = given.resolve(&scene).unwrap();
    let (first, _) = fogplanes::render::render_chunk(&r.scene, &r.options, 0..16_384, Control::none()).unwrap();
    let file = ck.join("planes_0-16384.npz");
    fogplanes::partial::parts::save_render_part(&file, &r.scene, &r.options, &first).unwrap();
    let gpu = first.devices.names()[0].clone();
    assert!(gpu.starts_with("gpu: "), "{gpu}");
    let out = d.join("resumed.exr");
    let o = fogplanes(&[
        "render",
        SCENE,
        "--resolution",
        "16x9",
        "--planes",
        "16400",
        "--checkpoint",
        path(&ck),
        "-o",
        path(&out),
    ]);
    let (stdout, stderr) = text(&o);
    assert!(o.status.success(), "{stderr}");
    assert!(stdout.contains(&format!("16384 of 16400 planes are done (gathered on {gpu})")), "{stdout}");
    assert!(stdout.contains(&format!("its planes were gathered on several devices (cpu; {gpu})")), "{stdout}");
    assert_eq!(devices_of(&out), format!("cpu; {gpu}"));
    // The checkpoint's node of both chunks records both devices too.
    let node = fogplanes::partial::parts::read_part(&ck.join("planes_0-16400.npz")).unwrap();
    assert_eq!(node.meta.render.unwrap().devices, vec!["cpu".to_string(), gpu]);
    let _ = std::fs::remove_dir_all(&d);
}

/// Refusals that the arguments alone decide come before any Vulkan driver is touched: with the
/// loader told to log (`VK_LOADER_DEBUG=info`), each is one line and exit 2, with no line of
/// the loader's (each was preceded by the loader and the driver: the CPU options with
/// `--device gpu` were three lines on a headless machine, two of them the driver's). A render
/// that goes on shows the loader's lines, so the test sees a driver where one is touched.
#[test]
fn refusals_the_arguments_decide_come_before_any_driver() {
    let d = dir("refusals");
    let (txt, npz) = (d.join("out.txt"), d.join("part.npz"));
    let exr = d.join("out.exr");
    let common = ["render", SCENE, "--resolution", "16x9", "--planes", "64", "--device", "gpu"];
    let cases: Vec<Vec<&str>> = vec![
        vec!["--kernel", "avx2"],
        vec!["--accelerator", "bvh"],
        vec!["-o", path(&txt)],
        vec!["--time-budget", "1", "--checkpoint", path(&d), "-o", path(&exr)],
        vec!["--partial", path(&txt)],
        vec!["--plane-range", "1:64", "--partial", path(&npz)],
        vec!["--exposure", "1", "-o", path(&exr)],
        vec!["--target-error", "2", "-o", path(&exr)],
    ];
    let log = [("VK_LOADER_DEBUG", "info")];
    for extra in &cases {
        let args: Vec<&str> = common.iter().chain(extra).copied().collect();
        let o = run_with(&args, &log, &[]);
        let (_, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.lines().count() == 1 && err.starts_with("error: "), "{extra:?}: {err}");
    }
    let table = ["table", SCENE, "--reference", "tests/hostile/not_an_exr.exr", "--device", "gpu", "--out"];
    let o = run_with(&[&table[..], &[path(&d)]].concat(), &log, &[]);
    assert!(o.status.code() == Some(2) && text(&o).1.lines().count() == 1, "{}", text(&o).1);
    if have_gpu("refusals_the_arguments_decide_come_before_any_driver") {
        let o = run_with(&[&common[..], &["-q", "-o", path(&exr)]].concat(), &log, &[]);
        let (_, err) = text(&o);
        assert!(o.status.success() && err.contains("Vulkan Loader"), "the loader does not log here: {err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// A GPU render on a machine without a desktop session (no `XDG_RUNTIME_DIR`, no Wayland or X
/// display: CI's case) prints nothing on stderr: Mesa's device-selection layer asked the
/// Wayland compositor for the default GPU when the instance enabled Wayland surfaces, and
/// libwayland-client printed `error: XDG_RUNTIME_DIR is invalid or not set in the environment.`
/// twice, which reads as a failure of ours.
#[test]
fn a_gpu_render_without_a_desktop_session_prints_nothing_on_stderr() {
    if !have_gpu("a_gpu_render_without_a_desktop_session_prints_nothing_on_stderr") {
        return;
    }
    let d = dir("quiet");
    let out = d.join("gpu.exr");
    let args = ["render", SCENE, "--resolution", "16x9", "--planes", "64", "--device", "gpu", "-o", path(&out)];
    let o = run_with(&args, &[], &["XDG_RUNTIME_DIR", "WAYLAND_DISPLAY", "WAYLAND_SOCKET", "DISPLAY"]);
    let (stdout, stderr) = text(&o);
    assert!(o.status.success(), "{stderr}");
    assert_eq!(stderr, "", "a GPU render's stderr holds lines that are not fogplanes'");
    assert!(stdout.contains("gpu: ") && stdout.contains("wrote "), "{stdout}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `fogplanes info` reads the file whole: a render's EXR cut short (half its bytes, or its last
/// ten) is refused in one line saying its pixel data is incomplete (it was described as a fine
/// image from its header alone); the whole file is described.
#[test]
fn info_tells_a_whole_exr_from_a_truncated_one() {
    let d = dir("info");
    let whole = d.join("whole.exr");
    let o = fogplanes(&["render", SCENE, "--resolution", "32x18", "--planes", "256", "-q", "-o", path(&whole)]);
    assert!(o.status.success(), "{}", text(&o).1);
    assert_eq!(devices_of(&whole), "cpu");
    let bytes = std::fs::read(&whole).unwrap();
    for keep in [bytes.len() / 2, bytes.len() - 10] {
        let cut = d.join(format!("cut_{keep}.exr"));
        std::fs::write(&cut, &bytes[..keep]).unwrap();
        let o = fogplanes(&["info", path(&cut)]);
        let (out, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{keep} of {} bytes: {out}{err}", bytes.len());
        assert!(err.lines().count() == 1 && err.contains("pixel data is incomplete"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// `fogplanes devices` lists every adapter with its index, back end, kind and largest binding,
/// one marked default; `--device gpu:N` gathers on adapter N (the default's image is
/// `--device gpu`'s, bit for bit); an index out of range, or a `FOGPLANES_GPU` one, is one line
/// naming the count, exit 2 (under `auto` as under `gpu`), and the list then marks none and
/// warns; a bad index (`gpu:x`, `gpu:+0`) is refused when parsed, and a work item's size that
/// `FOGPLANES_GPU_ITEM_PLANES` cannot give, or a `FOGPLANES_GPU_MATH` or `FOGPLANES_GPU_CHECKS`
/// that names no choice, in one line, exit 2.
#[test]
fn devices_lists_the_adapters_and_gpu_n_picks_one() {
    if !have_gpu("devices_lists_the_adapters_and_gpu_n_picks_one") {
        return;
    }
    let o = fogplanes(&["devices"]);
    let (out, err) = text(&o);
    assert!(o.status.success() && err.is_empty(), "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert!(!lines.is_empty());
    for (i, l) in lines.iter().enumerate() {
        assert!(
            l.starts_with(&format!("gpu:{i}  ")) && l.contains("(Vulkan, ") && l.contains("largest binding "),
            "{l}"
        );
    }
    let defaults: Vec<usize> = (0..lines.len()).filter(|&i| lines[i].ends_with("[default: --device gpu]")).collect();
    assert_eq!(defaults.len(), 1, "{out}");
    let n = lines.len();
    let d = dir("gpu-n");
    let render = |device: &str, out: &Path, env: &[(&str, &str)]| {
        let args =
            ["render", SCENE, "--resolution", "16x9", "--planes", "64", "-q", "--device", device, "-o", path(out)];
        // The tuning variables not given removed (their defaults, whatever this process was
        // given), so that each refusal is the one given's.
        let unset: Vec<&str> = TUNING.into_iter().filter(|v| !env.iter().any(|(k, _)| k == v)).collect();
        run_with(&args, env, &unset)
    };
    let (by_name, by_index) = (d.join("gpu.exr"), d.join("gpu_n.exr"));
    assert!(render("gpu", &by_name, &[]).status.success());
    let o = render(&format!("gpu:{}", defaults[0]), &by_index, &[]);
    assert!(o.status.success(), "{}", text(&o).1);
    let load = |p: &Path| fogplanes::film::Film::load_exr(p).unwrap().pixels;
    assert!(load(&by_name) == load(&by_index), "gpu:{} is not gpu's default", defaults[0]);
    let count = if n == 1 { "there is 1 adapter, gpu:0".to_string() } else { format!("there are {n} adapters") };
    let mut cases = vec![
        (format!("gpu:{n}"), vec![], format!("--device: gpu:{n}: {count}")),
        ("gpu".to_string(), vec![("FOGPLANES_GPU", "99")], format!("--device: FOGPLANES_GPU=99: {count}")),
        (
            "gpu".to_string(),
            vec![("FOGPLANES_GPU", "one")],
            "FOGPLANES_GPU=\"one\": not an adapter's index".to_string(),
        ),
        ("gpu:x".to_string(), vec![], "gpu:N takes an adapter's index".to_string()),
        ("gpu:+0".to_string(), vec![], "gpu:N takes an adapter's index".to_string()),
        ("gpu".to_string(), vec![("FOGPLANES_GPU", "+0")], "FOGPLANES_GPU=\"+0\": not an adapter's index".to_string()),
        // `auto` falls back to the CPU where there is no GPU, not where a variable is wrong.
        ("auto".to_string(), vec![("FOGPLANES_GPU", "99")], format!("--device: FOGPLANES_GPU=99: {count}")),
        (
            "auto".to_string(),
            vec![("FOGPLANES_GPU_MATH", "fast")],
            "--device: FOGPLANES_GPU_MATH=\"fast\": expected polynomials".to_string(),
        ),
        (
            "gpu".to_string(),
            vec![("FOGPLANES_GPU_ITEM_PLANES", "0")],
            "--device: FOGPLANES_GPU_ITEM_PLANES=\"0\": expected the planes of a GPU work item".to_string(),
        ),
    ];
    // The tuning's two-way choices: a value that names neither, refused with both named.
    for (variable, bad, default, other) in [
        ("FOGPLANES_GPU_MATH", "fast", "polynomials", "native"),
        ("FOGPLANES_GPU_CHECKS", "no", "on", "off"),
        ("FOGPLANES_GPU_ORIENTATIONS", "once", "per-hit", "table"),
        ("FOGPLANES_GPU_PIECES", "all", "joined", "apart"),
        ("FOGPLANES_GPU_BINNING", "tiles", "blocks", "flat"),
        ("FOGPLANES_GPU_K", "8", "uniform", "constant"),
        ("FOGPLANES_GPU_LANES", "warps", "blocks", "rows"),
    ] {
        let says = format!("--device: {variable}=\"{bad}\": expected {default} (the default) or {other}");
        cases.push(("gpu".to_string(), vec![(variable, bad)], says));
    }
    for (device, env, says) in cases {
        let o = render(&device, &d.join("no.exr"), &env);
        let (_, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{device} {env:?}: {err}");
        assert!(err.contains(&says), "{device} {env:?}: {err}");
        assert!(err.trim_end().lines().count() == 1 || device.starts_with("gpu:"), "{err}");
    }
    // The list marks the adapter FOGPLANES_GPU names, and none where it names none (with a
    // warning that `--device gpu` refuses it).
    let listed = |v: &str| {
        let o = run_with(&["devices"], &[("FOGPLANES_GPU", v)], &[]);
        let (out, err) = text(&o);
        assert!(o.status.success(), "FOGPLANES_GPU={v}: {err}");
        let marked: Vec<usize> =
            out.lines().enumerate().filter(|(_, l)| l.ends_with("[default: --device gpu]")).map(|(i, _)| i).collect();
        (marked, err)
    };
    let (marked, err) = listed(&(n - 1).to_string());
    assert!(marked == [n - 1] && err.is_empty(), "FOGPLANES_GPU={}: {marked:?} {err}", n - 1);
    let (marked, err) = listed(&n.to_string());
    assert!(marked.is_empty(), "FOGPLANES_GPU={n}: {marked:?}");
    assert!(
        err.trim_end().lines().count() == 1
            && err.contains(&format!("FOGPLANES_GPU={n}: {count}"))
            && err.contains("--device gpu refuses it"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// The choices fixed for measuring on a device (gpu/mod.rs `Tuning`): wgpu's shader runtime
/// checks off (`FOGPLANES_GPU_CHECKS=off`) gives the same pixels, bit for bit (no index leaves
/// its array, no loop is cut); the driver's exp, log and atan (`FOGPLANES_GPU_MATH=native`)
/// an image within 1e-8 relative MSE of the polynomials' (cmis-exact, which calls all four
/// functions; the bound that holds the GPU to the CPU elsewhere); K orientations made once a
/// gathering (`FOGPLANES_GPU_ORIENTATIONS=table`) the same pixels as made at each hit
/// (smis-exact and smis-cosine with K = 5: the same operations), as K a constant of the
/// pipeline (`FOGPLANES_GPU_K=constant`); a tile's pixels taken by the invocations in row order
/// (`FOGPLANES_GPU_LANES=rows`) the same pixels as in blocks of 8 x 4 (cmis-exact and smis-exact
/// with K = 5, at 40x20, whose tiles the image's edges cut in both directions); and each image
/// names its setting after the adapter, the default none.
#[test]
fn tuned_gpu_renders_keep_the_image_and_say_how_they_were_made() {
    if !have_gpu("tuned_gpu_renders_keep_the_image_and_say_how_they_were_made") {
        return;
    }
    let d = dir("tuned");
    let render_with = |name: &str, estimator: &[&str], env: &[(&str, &str)]| {
        let mut args = vec!["--resolution", "32x18", "--planes", "2048", "-q", "-e"];
        args.extend(estimator);
        let (pixels, _) = tuned_render(&d, name, &args, env);
        (pixels, devices_of(&d.join(format!("{name}.exr"))))
    };
    let render = |name: &str, env: &[(&str, &str)]| render_with(name, &["cmis-exact"], env);
    for estimator in ["smis-exact", "smis-cosine"] {
        let k = [estimator, "--orientations", "5"];
        let (per_hit, _) = render_with(&format!("{estimator} per hit"), &k, &[]);
        let (table, devices) =
            render_with(&format!("{estimator} table"), &k, &[("FOGPLANES_GPU_ORIENTATIONS", "table")]);
        assert!(devices.ends_with("tuned: orientations made once a gathering)"), "{devices}");
        assert!(table == per_hit, "{estimator}: the orientations made once a gathering changed the image");
        let (constant, devices) = render_with(&format!("{estimator} constant"), &k, &[("FOGPLANES_GPU_K", "constant")]);
        assert!(devices.ends_with("tuned: K a pipeline constant)"), "{devices}");
        assert!(constant == per_hit, "{estimator}: K a pipeline constant changed the image");
    }
    for estimator in [&["cmis-exact"][..], &["smis-exact", "--orientations", "5"]] {
        let name = estimator[0];
        let mut args = vec!["--resolution", "40x20", "--planes", "2048", "-q", "-e"];
        args.extend(estimator);
        let (blocks, _) = tuned_render(&d, &format!("{name} blocks"), &args, &[]);
        let (rows, _) = tuned_render(&d, &format!("{name} rows"), &args, &[("FOGPLANES_GPU_LANES", "rows")]);
        let devices = devices_of(&d.join(format!("{name} rows.exr")));
        assert!(devices.ends_with("tuned: lanes by rows)"), "{devices}");
        assert!(rows == blocks, "{name}: the pixels taken in row order changed the image");
    }
    let (base, base_devices) = render("default", &[]);
    assert!(!base_devices.contains("tuned"), "{base_devices}");
    let (unchecked, devices) = render("unchecked", &[("FOGPLANES_GPU_CHECKS", "off")]);
    assert!(devices.ends_with("tuned: no shader runtime checks)"), "{devices}");
    assert!(unchecked == base, "the shaders without runtime checks changed the image");
    let (native, devices) = render("native", &[("FOGPLANES_GPU_MATH", "native")]);
    assert!(devices.ends_with("tuned: the driver's exp, log and atan)"), "{devices}");
    let (mut num, mut den) = (0.0, 0.0);
    for (n, b) in native.iter().zip(&base) {
        (num, den) = (num + (n.as_dvec3() - b.as_dvec3()).length_squared(), den + b.as_dvec3().length_squared());
    }
    let rel = num / den;
    println!("the driver's exp, log and atan against the polynomials: relative MSE {rel:.2e}");
    assert!(den > 0.0 && rel <= 1e-8, "{rel}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A chunk's pieces (a ray set's share of its planes each) are joined into one structure on the
/// GPU, and their work items gathered in one dispatch along their sets made into one buffer
/// (gpu/planes.rs `GpuPlanes::join`): 2,048 planes in 16 ray sets, one chunk, are one gather
/// dispatch, not 32 (`FOGPLANES_GPU_PIECES=apart`: each group's two halves), and with the work
/// items' size fixed the same pixels, bit for bit (each piece's sums added to a pixel as they
/// were alone, the two halves of a group too, side by side along one ray set); with
/// smis-exact at K = 5 and the orientations' table too, whose rows are the joined planes', and
/// with 48 ray sets, whose 96 pieces are binned in three batches of a round (a batch's items were
/// once bounded by its tiles, not its tiles' segments, and 48 sets lost a tenth of the hits).
#[test]
fn a_chunks_pieces_are_gathered_in_one_dispatch_with_the_same_bits() {
    if !have_gpu("a_chunks_pieces_are_gathered_in_one_dispatch_with_the_same_bits") {
        return;
    }
    let d = dir("joined");
    let render = |name: &str, extra: &[&str], env: &[(&str, &str)]| {
        let mut args = vec!["--resolution", "40x24", "--planes", "2048"];
        args.extend(extra);
        let mut env = env.to_vec();
        env.push(("FOGPLANES_GPU_ITEM_PLANES", "8"));
        let (pixels, out_text) = tuned_render(&d, name, &args, &env);
        let dispatches = out_text
            .split(" gather dispatches")
            .next()
            .and_then(|head| head.rsplit(' ').next())
            .and_then(|n| n.parse::<u64>().ok())
            .unwrap_or_else(|| panic!("{name}: no dispatches in {out_text}"));
        (pixels, dispatches)
    };
    // Each group in two halves: 16 ray sets, 32 pieces; 48 ray sets, 96 pieces, binned in three
    // batches of one round (at most 32 segments a batch).
    for (extra, env, pieces) in [
        (&["-e", "smis-exact"][..], &[][..], 32),
        (&["-e", "smis-exact", "--orientations", "5"][..], &[("FOGPLANES_GPU_ORIENTATIONS", "table")][..], 32),
        (&["-e", "smis-exact", "--spp", "48"][..], &[][..], 96),
    ] {
        let (joined, one) = render("joined", extra, env);
        let apart_env: Vec<(&str, &str)> = env.iter().copied().chain([("FOGPLANES_GPU_PIECES", "apart")]).collect();
        let (apart, each) = render("apart", extra, &apart_env);
        assert_eq!((one, each), (1, pieces), "{extra:?}: the gather dispatches joined and apart");
        assert!(joined.iter().any(|p| p.x > 0.0), "{extra:?}: a black image says nothing");
        assert!(joined == apart, "{extra:?}: the join changed the image");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// The binning's first tier (blocks of 4 x 4 tiles, whose lists give each tile its candidates)
/// loses no (tile, plane) pair and adds none: the same image bits, hits and tests per hit as
/// every plane tested at every tile (`FOGPLANES_GPU_BINNING=flat`). The images are sized so
/// that blocks and tiles are cut by the image's edges (77 rows: 5 rows of tiles, 2 of blocks,
/// the last of one tile; a strip of 1,000 x 20 pixels, 16 blocks across of 63 tiles), with a
/// chunk's pieces joined (16 segments whose lists must stay in their order; 48 in two batches
/// of a round) and apart (one). It fails
/// where a block's list misses a plane: checked by taking a row of tiles off each block, and
/// then a column (`BLOCK - 1` in `reaches_block`'s rows, then in its columns), each of which
/// lost hits.
#[test]
fn the_binnings_blocks_give_each_tile_its_planes() {
    if !have_gpu("the_binnings_blocks_give_each_tile_its_planes") {
        return;
    }
    let d = dir("blocks");
    // What the summary says of the hits: their count and the tests per hit.
    let hits = |printed: &str| -> (u64, String) {
        let (head, tail) = printed.split_once(" hits (").unwrap_or_else(|| panic!("no hits in {printed}"));
        let n = head.rsplit(' ').next().and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("{printed}"));
        let tests = tail.split(" tests per hit").next().and_then(|t| t.rsplit(' ').next()).unwrap_or_default();
        (n, tests.to_string())
    };
    // 48 ray sets: a chunk's 48 pieces joined into two batches of one round (at most 32
    // segments a batch), the second's planes and region not the round's first.
    for (resolution, planes, spp, pieces) in
        [("150x77", "2048", "16", "joined"), ("1000x20", "1024", "16", "apart"), ("100x70", "2048", "48", "joined")]
    {
        let args = ["--resolution", resolution, "--planes", planes, "--spp", spp, "-e", "smis-exact"];
        let given = [("FOGPLANES_GPU_PIECES", pieces)];
        let (blocked, printed) = tuned_render(&d, "blocks", &args, &given);
        let flat_env = [given[0], ("FOGPLANES_GPU_BINNING", "flat")];
        let (flat, flat_printed) = tuned_render(&d, "flat", &args, &flat_env);
        assert!(
            flat_printed.contains("flat binning") && !printed.contains("flat binning"),
            "{printed}\n{flat_printed}"
        );
        let (n, tests) = hits(&printed);
        assert!(n > 0 && blocked.iter().any(|p| p.x > 0.0), "{resolution}: a black image says nothing");
        assert_eq!((n, tests), hits(&flat_printed), "{resolution} {pieces}: hits and tests per hit, blocks and flat");
        assert!(blocked == flat, "{resolution} {pieces}: the blocks changed the image");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// With the trace on (`FOGPLANES_TRACE=1`, for a device session's timeline), every GPU pass is
/// timed by its own timestamps and the trace ends with a table of them: each pass of the
/// binning's tiers, the gather and its reduction as often as the render ran them (a round's
/// reduction after each gather dispatch, a batch's six binning passes, or three when flat), the
/// rays' passes and the orientations' table where they ran; the passes of the rounds within
/// the summary's GPU time, which also holds the time between them. The image is the same bits
/// as without the trace. It fails where a round's time is taken from the wrong queries
/// (checked: the gather's start read as the round's), where a pass is left out of the table, or
/// where one tier's passes carry the other's names.
#[test]
fn the_trace_times_each_gpu_pass_and_keeps_the_image() {
    if !have_gpu("the_trace_times_each_gpu_pass_and_keeps_the_image") {
        return;
    }
    let d = dir("trace");
    let render = |name: &str, extra: &[&str], env: &[(&str, &str)]| {
        let mut args = vec!["--resolution", "40x24", "--planes", "2048"];
        args.extend(extra);
        tuned_run(&d, name, &args, env)
    };
    // The number before `word` in the summary.
    let before = |printed: &str, word: &str| -> f64 {
        let head = printed.split(word).next().unwrap_or_default();
        head.rsplit(' ').next().and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("no {word} in {printed}"))
    };
    for (extra, env, binning, orient) in [
        (&["-e", "smis-exact"][..], &[][..], 6, false),
        (
            &["-e", "smis-exact", "--orientations", "3"][..],
            &[("FOGPLANES_GPU_BINNING", "flat"), ("FOGPLANES_GPU_ORIENTATIONS", "table")][..],
            3,
            true,
        ),
    ] {
        let (plain, printed, _) = render("plain", extra, env);
        let traced_env: Vec<(&str, &str)> = env.iter().copied().chain([("FOGPLANES_TRACE", "1")]).collect();
        let (traced, traced_printed, err) = render("traced", extra, &traced_env);
        assert!(plain.iter().any(|p| p.x > 0.0), "{extra:?}: a black image says nothing");
        assert!(plain == traced, "{extra:?}: the trace changed the image");
        assert!(!printed.contains("GPU passes"), "{printed}");
        // The table: (pass, runs, ms) per row after its heading.
        let table: Vec<(String, u64, f64)> = err
            .lines()
            .skip_while(|l| !l.starts_with("GPU passes by their timestamps"))
            .skip(1)
            .map(|l| {
                let cells: Vec<&str> = l.split_whitespace().collect();
                let n = cells.len();
                assert!(n >= 5 && cells[n - 1].ends_with('%'), "a row of the table: {l}");
                (cells[..n - 4].join(" "), cells[n - 4].parse().unwrap(), cells[n - 3].parse().unwrap())
            })
            .collect();
        let runs = |pass: &str| table.iter().find(|r| r.0 == pass).map_or(0, |r| r.1);
        let dispatches = before(&traced_printed, " gather dispatches") as u64;
        let batches = runs("bin: scan");
        assert!(dispatches >= 1 && batches >= dispatches, "{extra:?}: {err}");
        assert_eq!((runs("gather"), runs("reduce")), (dispatches, dispatches), "{extra:?}: {err}");
        let bin =
            ["block_count", "block_scan", "block_scatter", "count", "scan", "scatter"].map(|p| format!("bin: {p}"));
        for (k, pass) in bin.iter().enumerate() {
            let expected = if k >= 6 - binning { batches } else { 0 };
            assert_eq!(runs(pass), expected, "{extra:?}: {pass}: {err}");
        }
        assert!(runs("reach") >= 1 && runs("rays") >= 1, "{extra:?}: {err}");
        assert_eq!(runs("orient") >= 1, orient, "{extra:?}: {err}");
        let named = bin.len() + ["gather", "reduce", "reach", "rays", "orient", "between passes"].len();
        assert!(table.len() <= named && table.iter().all(|r| r.1 >= 1), "{extra:?}: {err}");
        // The rounds' passes (the rays are not the gather's) within the GPU time, which holds
        // them and what lies between them, to the summary's 0.1 ms and the table's 1 us a row.
        let ms = |pass: &str| table.iter().find(|r| r.0 == pass).map_or(0.0, |r| r.2);
        let passes: f64 = table.iter().map(|r| r.2).sum::<f64>() - ms("rays") - ms("between passes");
        let gpu_ms = 1e3 * before(&traced_printed, " s (the reach and the binning");
        let slack = 0.05 + 0.001 * table.len() as f64;
        assert!(
            passes <= gpu_ms + slack && gpu_ms <= passes + ms("between passes") + slack,
            "{extra:?}: the passes' {passes} ms and the GPU time's {gpu_ms} ms: {err}"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}
