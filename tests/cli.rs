//! The command line: outputs are written whole, bad input gets one clear line and exit code 2.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fogplanes(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fogplanes")).args(args).output().expect("the binary runs")
}

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
    ] {
        let o = fogplanes(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
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

/// Ctrl-C during a render, with a plane count or on a time budget, leaves neither the output
/// nor a temporary file, and an existing output keeps its old contents.
#[test]
fn an_interrupted_render_leaves_no_file() {
    for how in [["--planes", "200000"], ["--time-budget", "30"]] {
        let dir = scratch("sigint");
        let out = dir.join("out.exr");
        std::fs::write(&out, b"old contents").unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_fogplanes"))
            .args(["render", "media_scenes/six_lights.toml", "--quiet", "-o", out.to_str().unwrap()])
            .args(how)
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(700));
        let killed = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
        assert!(killed.success());
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(130), "{how:?}");
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
    for bad in [vec!["--time-budget", "0"], vec!["--time-budget", "-1"], vec!["--time-budget", "1", "--planes", "100"]]
    {
        let o = fogplanes(&[&["render", "media_scenes/six_lights.toml", "--quiet"][..], &bad].concat());
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
