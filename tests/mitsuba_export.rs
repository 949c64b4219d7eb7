//! The Mitsuba export renders what fogplanes renders: `tests/mitsuba/check_export.py` exports
//! the benchmark scene, renders it with Mitsuba 3 and compares it block by block with
//! fogplanes' reference (within 5 standard errors per 8x8 block and channel, 4 for the image
//! means). About 20 s on 2 cores; as much again for the forward-scattering scene
//! (`media_scenes/forward_fog.toml`, Mitsuba's `hg`).
//!
//! `tests/mitsuba/check_outlines.py` follows Mitsuba's own camera rays, without noise, to where
//! they meet each light's outline: within 1e-3 pixel of fogplanes' projection without the fog
//! box, and of the model of Mitsuba's ray offset at the box's boundary with it (the red spot's
//! 0.008-pixel shift of docs/mitsuba_red_spot.md). About 2 s.
//!
//! They need `python3` with the `mitsuba` and `numpy` packages (`pip install mitsuba numpy`);
//! without them they say SKIPPED on standard error and return.

use std::process::Command;

fn python_imports(module: &str) -> bool {
    Command::new("python3").args(["-c", &format!("import {module}")]).output().is_ok_and(|o| o.status.success())
}

/// Whether python3 has mitsuba and numpy; says SKIPPED on standard error when not.
fn mitsuba_available() -> bool {
    if !python_imports("mitsuba") {
        eprintln!();
        eprintln!("==================================================================================");
        eprintln!("SKIPPED: the mitsuba Python package is not installed (pip install mitsuba)");
        eprintln!("         mitsuba_export checked nothing: python3 -c \"import mitsuba\" failed");
        eprintln!("==================================================================================");
        return false;
    }
    if !python_imports("numpy") {
        eprintln!();
        eprintln!("SKIPPED: the numpy Python package is not installed (pip install numpy)");
        return false;
    }
    true
}

#[test]
fn mitsuba_renders_the_exported_benchmark_scene_like_the_reference() {
    check_export("media_scenes/six_lights.toml", "64x36");
}

/// The same for forward-scattering fog (`forward_fog.toml`, `g = 0.85`): Mitsuba's `hg` phase
/// function against fogplanes' (docs/mathematics.md section 1.1), its halo around a lamp that
/// faces the camera and its dim beam seen from the side. A wrong sign of g, or a phase function
/// missing on either side, moves the halo's blocks by tens of standard errors.
#[test]
fn mitsuba_renders_forward_scattering_fog_like_the_reference() {
    check_export("media_scenes/forward_fog.toml", "64x40");
}

/// `check_export.py` on `scene` (relative to the repository) at `resolution`.
fn check_export(scene: &str, resolution: &str) {
    if !mitsuba_available() {
        return;
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/mitsuba/check_export.py");
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(scene);
    let o = Command::new("python3")
        .arg(script)
        .arg(&scene)
        .args([
            env!("CARGO_BIN_EXE_fogplanes"),
            "--resolution",
            resolution,
            // Half the samples of the first checks (2048 and 4096): half the time, the blocks'
            // z-scores as well calibrated (RMS 0.88 on forward_fog.toml), and a wrong sign of g
            // still about 190 standard errors off.
            "--spp",
            "1024",
            "--passes",
            "8",
            "--ref-spp",
            "2048",
            "--seed",
            "1",
        ])
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    eprintln!("{stdout}{stderr}");
    assert!(o.status.success(), "check_export.py exited {:?}:\n{stdout}\n{stderr}", o.status.code());
    assert!(stdout.contains("agreement: OK"), "{stdout}");
}

#[test]
fn mitsuba_sees_every_outline_where_fogplanes_does() {
    if !mitsuba_available() {
        return;
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/mitsuba/check_outlines.py");
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/media_scenes/six_lights.toml");
    let o =
        Command::new("python3").args([script, scene, env!("CARGO_BIN_EXE_fogplanes")]).output().expect("python3 runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    eprintln!("{stdout}{stderr}");
    assert!(o.status.success(), "check_outlines.py exited {:?}:\n{stdout}\n{stderr}", o.status.code());
    assert!(stdout.contains("outlines: OK"), "{stdout}");
}
