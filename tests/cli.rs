//! The command line: outputs are written whole, bad input gets one clear line and exit code 2.

use crate::common::fogplanes;
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogplanes-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn render_writes_exr_and_png_and_prints_a_summary() {
    let dir = scratch("render");
    for name in ["out.exr", "out.png"] {
        let out = dir.join(name);
        let o = fogplanes(&[
            "render",
            "media_scenes/six_lights.toml",
            "--resolution",
            "64x36",
            "--planes",
            "2000",
            "--quiet",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains("smis-exact: 2000 planes") && stdout.contains("hits"), "{stdout}");
    }
    assert_eq!(files_in(&dir), ["out.exr", "out.png"]);
    let film = fogplanes::film::Film::load_exr(&dir.join("out.exr")).unwrap();
    assert_eq!((film.width, film.height), (64, 36));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `FOGPLANES_TRACE=1`: the render's timeline on stderr, a line a step (start, end and length in
/// milliseconds since the process started, the thread, the step), the steps of the render in
/// it; without it, nothing.
#[test]
fn a_traced_render_prints_its_timeline() {
    let dir = scratch("trace");
    let out = dir.join("out.exr");
    let args = ["render", "media_scenes/six_lights.toml", "--resolution", "32x18", "--planes", "2000", "-q", "-o"];
    let run = |trace: &str| {
        Command::new(env!("CARGO_BIN_EXE_fogplanes"))
            .args(args)
            .arg(&out)
            .env("FOGPLANES_TRACE", trace)
            .output()
            .unwrap()
    };
    let o = run("1");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    let mut steps = Vec::new();
    for line in err.lines() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        assert!(fields.len() >= 5, "not a step: {line:?}");
        let [start, end, length] = [0, 1, 2].map(|i| fields[i].parse::<f64>().unwrap());
        assert!(0.0 <= start && start <= end && (end - start - length).abs() < 2e-3, "{line:?}");
        assert!(fields[3].starts_with("ThreadId("), "{line:?}");
        steps.push(fields[4..].join(" "));
    }
    for step in ["process started", "planes sampled", "first window prepared", "chunks rendered", "image finished"] {
        assert!(steps.iter().any(|s| s == step), "no {step:?} in\n{err}");
    }
    let o = run("");
    assert!(o.status.success() && o.stderr.is_empty(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_missing_output_directory_is_reported_before_rendering() {
    let o = fogplanes(&["render", "media_scenes/six_lights.toml", "--quiet", "-o", "/no/such/dir/x.exr"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("does not exist"), "{err}");
    assert!(o.stdout.is_empty(), "nothing was rendered");
}

#[test]
fn bad_arguments_exit_2() {
    for args in [
        vec!["render", "media_scenes/six_lights.toml", "--planes", "0"],
        vec!["render", "media_scenes/six_lights.toml", "--estimator", "magic"],
        vec!["render", "media_scenes/six_lights.toml", "--resolution", "0x10"],
        vec!["render", "media_scenes/six_lights.toml", "--resolution", "100000x100000"],
        vec!["reference", "media_scenes/six_lights.toml", "--resolution", "32000x32000"],
        vec!["table", "media_scenes/six_lights.toml", "--reference", "no.exr", "--resolution", "32000x32000"],
        vec!["render", "media_scenes/six_lights.toml", "--planes", "1000000000000"],
        vec!["render", "media_scenes/six_lights.toml", "-o", "x.jpg"],
        vec!["render", "media_scenes/six_lights.toml", "--estimator", "cmis-exact", "--orientations", "4"],
        vec!["render", "no_such_scene.toml"],
        vec!["compare", "no_such.exr", "other.exr"],
        vec!["render", "media_scenes/six_lights.toml", "--exposure", "inf"],
        vec!["table", "media_scenes/six_lights.toml", "--reference", "no.exr", "--sweep-seeds", "0"],
        vec!["table", "media_scenes/six_lights.toml", "--reference", "no.exr", "--equal-time", "-1"],
        vec!["table", "media_scenes/six_lights.toml", "--reference", "no.exr", "--samplers", "sobol,sobol"],
        vec!["scaling", "media_scenes/six_lights.toml", "--resolutions", "0x10"],
    ] {
        let o = fogplanes(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    // A negative count is a bad value of its setting, not an unknown flag: clap took `-1` for one
    // and advised `-- -1`, which a value cannot be.
    for (flag, value) in
        [("--seed", "-1"), ("--planes", "-5"), ("--spp", "-2"), ("--threads", "-3"), ("--orientations", "-1")]
    {
        let o = fogplanes(&["render", "media_scenes/six_lights.toml", flag, value]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(&format!("invalid value '{value}' for '{flag} ")) && !err.contains("tip"), "{err}");
        // Every count in the same words: u32 ones (--spp, --orientations) were clap's ranged
        // numbers, "-2 is not in 0..=4294967295".
        assert!(err.contains("': expected a whole number, 0 or more"), "{flag} {value}: {err}");
        assert!(!err.contains("invalid digit") && !err.contains("is not in"), "{err}");
        // The usage shown is the command's, as with any other error of its arguments (the
        // reworded ones showed the root's, `fogplanes <COMMAND>`).
        assert!(err.contains("Usage: fogplanes render [OPTIONS] <SCENE>"), "{flag} {value}: {err}");
    }
    let o = fogplanes(&["table", "media_scenes/six_lights.toml", "--reference", "r.exr", "--sweep", "10,x"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("Usage: fogplanes table [OPTIONS] --reference <REF> <SCENE>"), "{err}");
    // So do clap's own errors of a value, outside a list or refused by a setting's parser (they
    // showed none), with what they said before.
    for (args, said, usage) in [
        (
            vec!["render", "media_scenes/six_lights.toml", "-e", "foo"],
            "[possible values: unweighted,",
            "render [OPTIONS] <SCENE>",
        ),
        (
            vec!["render", "media_scenes/six_lights.toml", "--device", "tpu"],
            "unknown device \"tpu\"",
            "render [OPTIONS] <SCENE>",
        ),
        (
            vec!["reference", "media_scenes/six_lights.toml", "--resolution", "10"],
            "expected WIDTHxHEIGHT",
            "reference [OPTIONS] <SCENE>",
        ),
    ] {
        let o = fogplanes(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(said) && err.contains(&format!("Usage: fogplanes {usage}")), "{args:?}: {err}");
    }
    // A count that is no whole number, or too large for its type, is said as such, not in
    // Rust's words ("invalid digit found in string").
    let scene = "media_scenes/six_lights.toml";
    for (args, why) in [
        (vec!["render", scene, "--planes", "1.5"], "expected a whole number, 0 or more"),
        (vec!["table", scene, "--reference", "no.exr", "--sweep", "10,x"], "expected a whole number, 0 or more"),
        (vec!["render", scene, "--seed", "99999999999999999999999"], "too large for the setting"),
        (vec!["render", scene, "--spp", "4294967296"], "'--spp <J>': too large for the setting"),
        (vec!["reference", scene, "--spp", "-16"], "'--spp <N>': expected a whole number, 0 or more"),
        (vec!["table", scene, "--reference", "no.exr", "--sweep-seeds", "-1"], "expected a whole number, 0 or more"),
        (vec!["table", scene, "--reference", "no.exr", "--orientations", "4,-3"], "expected a whole number, 0 or more"),
        // A value named twice in a list of the table, named (a K was dropped without a word).
        (vec!["table", scene, "--reference", "no.exr", "--orientations", "2,2"], "--orientations: 2 is named twice"),
        (vec!["table", scene, "--reference", "no.exr", "--orientations", "4,3,4"], "--orientations: 4 is named twice"),
        (vec!["table", scene, "--reference", "no.exr", "--sweep", "5120,5120"], "--sweep: 5120 is named twice"),
        (
            vec!["scaling", scene, "--lobes", "1.5"],
            "--lobes: the share of the planes swept along the lobe must be between 0 and 1, got 1.5",
        ),
        // A share of the planes, told in the library's words with the flag.
        (
            vec!["render", scene, "--lobes", "1.5"],
            "--lobes: the share of the planes swept along the lobe must be between 0 and 1, got 1.5",
        ),
        (
            vec!["render", scene, "--lobes", "-0.5"],
            "--lobes: the share of the planes swept along the lobe must be between 0 and 1, got -0.5",
        ),
        // In every form of a float, not only clap's idea of a negative number (`-1e-3` was an
        // unknown flag '-1', with the advice '-- -1').
        (
            vec!["render", scene, "--lobes", "-1e-3"],
            "--lobes: the share of the planes swept along the lobe must be between 0 and 1, got -0.001",
        ),
        (
            vec!["render", scene, "--lobes", "-.5"],
            "--lobes: the share of the planes swept along the lobe must be between 0 and 1, got -0.5",
        ),
        (vec!["render", scene, "--time-budget", "-1E-3"], "--time-budget: must be a positive number of seconds"),
        (
            vec!["table", scene, "--reference", "no.exr", "--lobes", "nan"],
            "--lobes: the share of the planes swept along the lobe must be between 0 and 1, got NaN",
        ),
        // A pair whose first number is negative is a bad value too, not an unknown flag (clap
        // took `-5x3` for one and advised `-- -5x3`), said as the counts are.
        (vec!["render", scene, "--resolution", "-5x3"], "\"-5\" in \"-5x3\": expected a whole number, 0 or more"),
        (vec!["reference", scene, "--resolution", "4x-3"], "\"-3\" in \"4x-3\": expected a whole number, 0 or more"),
        (vec!["scaling", scene, "--resolutions", "8x8,-1x2"], "\"-1\" in \"-1x2\": expected a whole number"),
        (vec!["render", scene, "--resolution", "99999999999x2"], "\"99999999999\" in \"99999999999x2\": too large"),
        (
            vec!["render", scene, "--plane-range", "-2560:5120", "--partial", "p.npz"],
            "\"-2560\" in \"-2560:5120\": expected a whole number, 0 or more",
        ),
        (
            vec!["reference", scene, "--rows", "0:-8", "--partial", "p.npz"],
            "\"-8\" in \"0:-8\": expected a whole number, 0 or more",
        ),
        // An error image a budget left one group for: the budget named, not --planes, which a
        // render on a budget does not take.
        (
            vec![
                "render",
                scene,
                "--resolution",
                "32x18",
                "--time-budget",
                "1e-6",
                "--stderr-image",
                "se.exr",
                "-o",
                "x.exr",
            ],
            "--time-budget: an error image needs planes in at least two groups, and the budget ended after",
        ),
        // A flag after a pair's flag is a flag: the pair's missing value said as such.
        (vec!["render", scene, "--resolution", "--planes", "256"], "a value is required for '--resolution <WxH>'"),
        // Quoted as given, not narrowed to the rows' type first (it said "rows 0:4294967295").
        (
            vec!["reference", scene, "--rows", "0:18446744073709551615", "--partial", "p.npz", "--uniform"],
            "rows 0:18446744073709551615 are not a band of the image's 360 rows",
        ),
    ] {
        let o = fogplanes(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(why) && !err.contains("invalid digit") && !err.contains("tip:"), "{args:?}: {err}");
    }
}

/// Every file in tests/bad_scenes gives one error line naming the file, exit code 2, no
/// output.
#[test]
fn every_broken_scene_gives_one_clear_error() {
    let dir = scratch("bad");
    let mut checked = 0;
    for entry in std::fs::read_dir("tests/bad_scenes").unwrap() {
        let path = entry.unwrap().path();
        let out = dir.join("out.exr");
        let o = fogplanes(&["render", path.to_str().unwrap(), "--quiet", "-o", out.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", path.display());
        assert_eq!(err.lines().count(), 1, "{}: one line expected, got:\n{err}", path.display());
        // Nothing of the file reaches the terminal raw (an escape sequence in a light's name did).
        assert!(!err.trim_end().chars().any(char::is_control), "{}: {err:?}", path.display());
        assert!(err.contains(path.file_name().unwrap().to_str().unwrap()), "{}: {err}", path.display());
        assert!(files_in(&dir).is_empty(), "{}: an output was written", path.display());
        checked += 1;
    }
    assert!(checked >= 10);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn export_writes_mitsuba_xml_and_refuses_bad_input() {
    let dir = scratch("export");
    let scene = std::fs::canonicalize("media_scenes/six_lights.toml").unwrap();
    // The default name is <scene name>.xml in the working directory.
    let o = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
        .args(["export", scene.to_str().unwrap(), "--format", "mitsuba"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("six_lights.xml"));
    assert_eq!(files_in(&dir), ["six_lights.xml"]);
    let text = std::fs::read_to_string(dir.join("six_lights.xml")).unwrap();
    assert!(text.contains(r#"<integrator type="volpath">"#) && text.ends_with("</scene>\n"), "{text}");
    assert_eq!(text.matches(r#"<shape type="rectangle""#).count(), 6);

    let out = dir.join("small.xml");
    let o = fogplanes(
        &["export", "media_scenes/six_lights.toml", "-f", "mitsuba", "--resolution", "64x36", "-o"]
            .into_iter()
            .chain([out.to_str().unwrap()])
            .collect::<Vec<_>>(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let small = std::fs::read_to_string(&out).unwrap();
    assert!(small.contains(r#"<default name="resx" value="64"/>"#), "{small}");
    assert_eq!(files_in(&dir), ["six_lights.xml", "small.xml"]);

    for args in [
        vec!["export", "media_scenes/six_lights.toml"],
        vec!["export", "media_scenes/six_lights.toml", "--format", "pbrt"],
        vec!["export", "media_scenes/six_lights.toml", "--format", "mitsuba", "-o", "/no/such/dir/x.xml"],
        vec!["export", "media_scenes/six_lights.toml", "--format", "mitsuba", "--resolution", "0x10"],
        vec!["export", "no_such_scene.toml", "--format", "mitsuba"],
    ] {
        let o = fogplanes(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    assert_eq!(files_in(&dir), ["six_lights.xml", "small.xml"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_huge_scene_file_is_refused_before_reading() {
    let dir = scratch("huge");
    let path = dir.join("huge.toml");
    std::fs::File::create(&path).unwrap().set_len(100 << 20).unwrap();
    let o = fogplanes(&["render", path.to_str().unwrap(), "--quiet", "-o", dir.join("o.exr").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("104857600 bytes") && err.lines().count() == 1, "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_closed_pipe_is_not_a_panic() {
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
        .args(["compare", "--help"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert!(!String::from_utf8_lossy(&o.stderr).contains("panicked"));
}

/// Ctrl-C (or SIGTERM) during a render, with a plane count or on a time budget, leaves neither
/// the output nor a temporary file, and an existing output keeps its old contents.
#[test]
fn an_interrupted_render_leaves_no_file() {
    for (signal, how) in
        [("-INT", ["--planes", "200000"]), ("-INT", ["--time-budget", "30"]), ("-TERM", ["--planes", "200000"])]
    {
        let dir = scratch("sigint");
        let out = dir.join("out.exr");
        std::fs::write(&out, b"old contents").unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
            .args(["render", "media_scenes/six_lights.toml", "--quiet", "-o", out.to_str().unwrap()])
            .args(how)
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(700));
        let killed = Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap();
        assert!(killed.success());
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(130), "{signal} {how:?}");
        assert_eq!(files_in(&dir), ["out.exr"], "{how:?}");
        assert_eq!(std::fs::read(&out).unwrap(), b"old contents", "{how:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// A render on a time budget writes its image and says how many planes and passes it took;
/// the budget must be a positive number and excludes a plane count.
#[test]
fn a_render_on_a_time_budget_reports_its_planes_and_passes() {
    let dir = scratch("budget");
    let out = dir.join("out.exr");
    let o = fogplanes(&[
        "render",
        "media_scenes/six_lights.toml",
        "--resolution",
        "64x36",
        "--time-budget",
        "0.5",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("plane passes") && stdout.contains("planes"), "{stdout}");
    assert_eq!(files_in(&dir), ["out.exr"]);
    for (bad, says) in [
        (vec!["--time-budget", "0"], "--time-budget: must be a positive number of seconds up to 1e6, got 0"),
        // A negative number parses (as --exposure -1 does), to be refused with one clear line.
        (vec!["--time-budget", "-1"], "--time-budget: must be a positive number of seconds up to 1e6, got -1"),
        (
            vec!["--time-budget", "1", "--planes", "100"],
            "--planes: a render on a time budget chooses its own plane count",
        ),
    ] {
        let o = fogplanes(&[&["render", "media_scenes/six_lights.toml", "--quiet"][..], &bad].concat());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {err}");
        assert!(err.starts_with(&format!("error: {says}")) && err.lines().count() == 1, "{bad:?}: {err}");
    }
    // The scene's plane count is the scene's: no --planes was given, none is named (the table
    // holds all its planes; a render would hold one chunk of them at a time).
    let scene = dir.join("many.toml");
    let text = std::fs::read_to_string("media_scenes/six_lights.toml").unwrap();
    let planes = 1u64 << 27;
    std::fs::write(&scene, format!("{}[render]\nplanes = {planes}\n", text.split("[render]").next().unwrap())).unwrap();
    let o = fogplanes(&[
        "table",
        scene.to_str().unwrap(),
        "--quiet",
        "--reference",
        "none.exr",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.starts_with(&format!("error: the scene's render.planes: 640x360 pixels with {planes} planes")),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A small EXR of the scene, of whole pixels as the table's (a stand-in reference for `table`).
fn small_reference(dir: &Path) -> PathBuf {
    let path = dir.join("ref.exr");
    let o = fogplanes(&[
        "render",
        "media_scenes/six_lights.toml",
        "--resolution",
        "32x18",
        "--planes",
        "200",
        "--quiet",
        "-o",
        path.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    path
}

/// A NaN exposure once wrote an all-black PNG with exit code 0.
#[test]
fn a_non_finite_exposure_is_refused_before_any_work() {
    let dir = scratch("exposure");
    let reference = small_reference(&dir);
    let (png, report) = (dir.join("x.png"), dir.join("report"));
    let scene = "media_scenes/six_lights.toml";
    let small = ["--resolution", "32x18", "--quiet"];
    for args in [
        vec!["render", scene, "--planes", "200", "-o", png.to_str().unwrap()],
        vec!["reference", scene, "--spp", "4", "-o", png.to_str().unwrap()],
        vec![
            "table",
            scene,
            "--reference",
            reference.to_str().unwrap(),
            "--no-sweep",
            "--out",
            report.to_str().unwrap(),
        ],
    ] {
        for exposure in
            [&["--exposure=nan"][..], &["--exposure=-inf"], &["--exposure", "-inf"], &["--exposure", "-nan"]]
        {
            let o = fogplanes(&[&args[..], &small, exposure].concat());
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{args:?} {exposure:?}: {err}");
            assert!(err.starts_with("error: --exposure: must be a finite number of stops"), "{err}");
            assert!(o.stdout.is_empty(), "{args:?}: work was done");
            assert_eq!(files_in(&dir), ["ref.exr"], "{args:?} {exposure:?}");
        }
    }
    // A negative exposure in a float's exponent form is a value, not a flag (clap took `-1e-1`
    // for an unknown flag `-1`).
    let o = fogplanes(
        &[&["render", scene, "--planes", "200", "-o", png.to_str().unwrap()][..], &small, &["--exposure", "-1e-1"]]
            .concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(png.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--exposure` tone-maps a PNG; with only EXR (or part) outputs it was once ignored without a
/// word. Now it is one error line before any work, and accepted wherever a PNG is written.
#[test]
fn an_exposure_without_a_png_output_is_refused_before_any_work() {
    let dir = scratch("exposure-exr");
    let scene = "media_scenes/six_lights.toml";
    let small = ["--resolution", "32x18", "--quiet", "--exposure", "1.5"];
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (exr, png, part) = (path("x.exr"), path("x.png"), path("part.npz"));
    for args in [
        vec!["render", scene, "--planes", "200", "-o", &exr],
        vec!["render", scene, "--planes", "200", "--partial", &part],
        vec!["reference", scene, "--spp", "4", "-o", &exr, "--stderr-image", &path("se.exr")],
        vec!["reference", scene, "--spp", "4", "--uniform", "--partial", &part],
    ] {
        let o = fogplanes(&[&args[..], &small].concat());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.starts_with("error: --exposure: tone-maps PNG images only") && err.lines().count() == 1, "{err}");
        assert!(o.stdout.is_empty() && files_in(&dir).is_empty(), "{args:?}: work was done");
    }
    // The default output is an EXR too.
    let o = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
        .current_dir(&dir)
        .args(["render", &std::fs::canonicalize(scene).unwrap().to_string_lossy()])
        .args(small)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(files_in(&dir).is_empty());
    // A PNG among the outputs: the exposure applies to it.
    for args in [
        vec!["render", scene, "--planes", "200", "-o", &png],
        vec!["reference", scene, "--spp", "4", "-o", &exr, "--stderr-image", &png],
    ] {
        let o = fogplanes(&[&args[..], &small].concat());
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `fogplanes --help` opens with a summary that names every command (it once left out merge
/// and export).
#[test]
fn the_help_summary_names_every_command() {
    let o = fogplanes(&["--help"]);
    let help = String::from_utf8_lossy(&o.stdout);
    let summary = help.lines().next().unwrap();
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    assert!(commands.len() >= 7, "{help}");
    for c in commands {
        assert!(summary.contains(c), "the summary {summary:?} does not name `{c}`");
    }
}

/// Every output is checked before any work: a table whose page cannot be written once
/// rendered everything and replaced table.md, table.json and panel.png before failing, and a
/// reference written twice to one file kept only its standard error.
#[test]
fn every_output_is_checked_before_any_work() {
    let dir = scratch("outputs");
    let reference = small_reference(&dir);
    let report = dir.join("report");
    for blocked in ["index.html", "table.md", "table.json", "panel.png", "error_vs_time.png", "error_vs_time.svg"] {
        let _ = std::fs::remove_dir_all(&report);
        std::fs::create_dir_all(report.join(blocked)).unwrap();
        let o = fogplanes(&[
            "table",
            "media_scenes/six_lights.toml",
            "--reference",
            reference.to_str().unwrap(),
            "--resolution",
            "32x18",
            "--planes",
            "200",
            "--sweep",
            "100,200",
            "--sweep-seeds",
            "1",
            "--samplers",
            "sobol",
            "--quiet",
            "--out",
            report.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{blocked}: {err}");
        assert!(err.contains(blocked) && err.contains("is a directory") && err.lines().count() == 1, "{err}");
        assert!(o.stdout.is_empty(), "{blocked}: the table was rendered");
        assert_eq!(files_in(&report), [blocked], "{blocked}");
    }

    let out = dir.join("r.exr");
    std::fs::write(&out, b"old contents").unwrap();
    let same = dir.join(".").join("r.exr");
    for twice in [&out, &same] {
        let o = fogplanes(&[
            "reference",
            "media_scenes/six_lights.toml",
            "--resolution",
            "32x18",
            "--spp",
            "4",
            "--quiet",
            "-o",
            out.to_str().unwrap(),
            "--stderr-image",
            twice.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains("is named twice as an output") && err.lines().count() == 1, "{err}");
        assert!(o.stdout.is_empty());
        assert_eq!(std::fs::read(&out).unwrap(), b"old contents");
    }
    assert_eq!(files_in(&dir), ["r.exr", "ref.exr", "report"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A checkpoint directory is kept apart from the outputs before any work: `render -o x.exr
/// --checkpoint x.exr` made the directory x.exr, rendered, and failed (exit code 1) to move the
/// image onto it; with `--stderr-image x.exr` the image was written and its error image lost.
#[test]
fn a_checkpoint_named_as_an_output_is_refused_before_any_work() {
    let dir = scratch("checkpoint-output");
    let (image, stderr, record) = (dir.join("x.exr"), dir.join("se.exr"), dir.join("s.json"));
    let render = ["render", "media_scenes/six_lights.toml", "--resolution", "16x9", "--planes", "200", "-q"];
    for (extra, checkpoint) in [
        (vec![], &image),
        (vec!["--stderr-image", stderr.to_str().unwrap()], &stderr),
        (vec!["--stderr-image", stderr.to_str().unwrap()], &image),
        (vec!["--schedule-record", record.to_str().unwrap()], &record),
    ] {
        let mut args = render.to_vec();
        args.extend(["-o", image.to_str().unwrap(), "--checkpoint", checkpoint.to_str().unwrap()]);
        args.extend(&extra);
        let o = fogplanes(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("is named twice as an output") && err.lines().count() == 1, "{args:?}: {err}");
        assert!(o.stdout.is_empty() && files_in(&dir).is_empty(), "{args:?}: {:?}", files_in(&dir));
    }
    let reference = ["reference", "media_scenes/six_lights.toml", "--resolution", "16x9", "--spp", "4", "-q"];
    let mut args = reference.to_vec();
    args.extend(["-o", image.to_str().unwrap(), "--stderr-image", stderr.to_str().unwrap()]);
    args.extend(["--checkpoint", stderr.to_str().unwrap()]);
    let o = fogplanes(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("is named twice as an output") && err.lines().count() == 1, "{err}");
    assert!(o.stdout.is_empty() && files_in(&dir).is_empty(), "{:?}", files_in(&dir));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// SIGTERM while the image is being written removes the temporary file as Ctrl-C does: the
/// output is either its old contents or the whole new image, and nothing is left beside it.
#[test]
fn sigterm_during_a_write_leaves_no_temporary_file() {
    let dir = scratch("sigterm");
    let out = dir.join("out.exr");
    let mut caught = 0;
    for _ in 0..10 {
        std::fs::write(&out, b"old contents").unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
            .args(["render", "media_scenes/six_lights.toml", "--resolution", "1024x576", "--planes", "1", "--quiet"])
            .args(["-o", out.to_str().unwrap()])
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Signal the moment the temporary file appears.
        let mut signalled = false;
        while child.try_wait().unwrap().is_none() {
            if files_in(&dir).iter().any(|f| f.ends_with(".tmp")) {
                let _ = Command::new("kill").args(["-TERM", &child.id().to_string()]).status();
                signalled = true;
                break;
            }
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
        let status = child.wait().unwrap();
        assert_eq!(files_in(&dir), ["out.exr"], "{status:?}");
        let whole = std::fs::read(&out).unwrap() == b"old contents" || fogplanes::film::Film::load_exr(&out).is_ok();
        assert!(whole, "{status:?}: a partial output");
        if signalled && status.code() == Some(130) {
            caught += 1;
        } else {
            assert_eq!(status.code(), Some(0), "signalled {signalled}");
        }
        if caught >= 2 {
            break;
        }
    }
    assert!(caught >= 1, "never caught a write under way");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// What a line quotes of a name acts on no terminal: a scene file named with an escape
/// sequence, a newline and a text-direction override gives its name to the image's record, and
/// an output path holds the same. `render`'s `wrote` line, `info`'s record and `compare`'s
/// warning of different scenes write them as escapes, each line whole (they reached the
/// terminal raw; the error lines already wrote them so).
#[test]
fn names_that_act_on_a_terminal_are_written_as_escapes() {
    use fogplanes::error::acts_on_terminal;
    let dir = scratch("names");
    let scene = dir.join("e\u{1b}[31mv\nil\u{202e}.toml");
    std::fs::copy("media_scenes/six_lights.toml", &scene).unwrap();
    let out = dir.join("o\u{1b}[2Jx\u{2028}.exr");
    let small = ["--resolution", "32x18", "--planes", "256"];
    let o = fogplanes(&[&["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap()][..], &small].concat());
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let clean = |text: &str| text.lines().all(|l| !l.chars().any(acts_on_terminal));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(clean(&stdout) && stdout.lines().count() == 2, "{stdout:?}");
    assert!(stdout.contains("o\\u{1b}[2Jx\\u{2028}.exr ("), "{stdout}");
    let info = fogplanes(&["info", out.to_str().unwrap()]);
    let record = String::from_utf8_lossy(&info.stdout).into_owned();
    assert!(clean(&record) && record.contains("scene_name: e\\u{1b}[31mv\\nil\\u{202e}\n"), "{record:?}");
    let other = dir.join("other.exr");
    let o =
        fogplanes(&[&["render", "media_scenes/forward_fog.toml", "-o", other.to_str().unwrap()][..], &small].concat());
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let o = fogplanes(&["compare", out.to_str().unwrap(), other.to_str().unwrap()]);
    let warned = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(clean(&warned) && warned.contains("different scenes (e\\u{1b}[31mv\\nil\\u{202e} and"), "{warned:?}");
    // The warning's reference path too.
    let o = fogplanes(&["compare", other.to_str().unwrap(), out.to_str().unwrap()]);
    let warned = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(clean(&warned) && warned.contains("o\\u{1b}[2Jx\\u{2028}.exr: the image and the reference"), "{warned:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A table of a black scene (its one light on the box's ceiling, facing out of the box: every
/// MSE 0) prints no `inf` or `NaN`: an efficiency of an MSE of 0, a ratio of two of them and a
/// time per hit without hits are `-` in the Markdown and null in the JSON, and the render's
/// summary gives no figure per hit.
#[test]
fn a_table_of_a_black_scene_prints_no_infinity() {
    let dir = scratch("black");
    let scene = dir.join("black.toml");
    let text = "[camera]\nposition = [0.0, 1.0, 5.0]\nlook_at = [0.0, 1.0, 0.0]\nup = [0.0, 1.0, 0.0]\nvfov_deg = 40.0\n\
        resolution = [32, 18]\n\n[medium]\nmin = [-2.0, 0.0, -2.0]\nmax = [2.0, 2.0, 2.0]\nsigma_s = 0.1\nsigma_a = 0.05\n\n\
        [[light]]\ncorner = [-0.5, 2.0, -0.5]\nedge_u = [0.0, 0.0, 1.0]\nedge_v = [1.0, 0.0, 0.0]\nradiance = 4\n";
    std::fs::write(&scene, text).unwrap();
    let (reference, out) = (dir.join("ref.exr"), dir.join("table"));
    let o = fogplanes(&["reference", scene.to_str().unwrap(), "--spp", "4", "-o", reference.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let args = ["--reference", reference.to_str().unwrap(), "--planes", "256", "--no-sweep", "--out"];
    let o = fogplanes(&[&["table", scene.to_str().unwrap()][..], &args, &[out.to_str().unwrap()]].concat());
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap()).unwrap();
    assert!(!md.contains("inf") && !md.contains("NaN") && md.contains("| - / - |"), "{md}");
    let row = &json["rows"][0];
    assert!(row["hits"] == 0 && row["gather_ns_per_hit"].is_null() && row["efficiency_total"].is_null(), "{row}");
    let o =
        fogplanes(&["render", scene.to_str().unwrap(), "--planes", "256", "-o", dir.join("x.exr").to_str().unwrap()]);
    let summary = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(summary.contains(" 0 hits, gather ") && !summary.contains("ns/hit"), "{summary}");
    std::fs::remove_dir_all(&dir).unwrap();
}
