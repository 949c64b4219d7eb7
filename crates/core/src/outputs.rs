//! Every output of a command checked before any work: each can be written, none is a
//! directory, and no file is named twice (the second write would replace the first, as
//! `reference -o x.exr --stderr-image x.exr` once lost its reference).

use crate::error::{Error, Result};
use crate::film::{check_image_output, check_writable};
use std::path::{Path, PathBuf};

/// An output file of a command.
#[derive(Clone, Copy, Debug)]
pub enum Output<'a> {
    /// An image: `.exr` or `.png` ([`check_image_output`]).
    Image(&'a Path),
    /// Any other file (Markdown, JSON, SVG, HTML).
    File(&'a Path),
}

impl Output<'_> {
    pub fn path(&self) -> &Path {
        match self {
            Output::Image(p) | Output::File(p) => p,
        }
    }
}

/// Checks every output before any work: writable ([`check_writable`]), an image's format
/// known, and each file named once (two names of one file count as one: `./x.exr` and
/// `x.exr`, or a link and its target).
pub fn check_outputs(outputs: &[Output<'_>]) -> Result<()> {
    let mut seen: Vec<(PathBuf, &Path)> = Vec::with_capacity(outputs.len());
    for output in outputs {
        match output {
            Output::Image(p) => check_image_output(p)?,
            Output::File(p) => check_writable(p)?,
        }
        let path = output.path();
        let id = identity(path);
        if let Some((_, first)) = seen.iter().find(|(other, _)| *other == id) {
            let also = if *first == path { String::new() } else { format!(" (also as {})", first.display()) };
            return Err(Error::bad_input(path, format!("is named twice as an output{also}")));
        }
        seen.push((id, path));
    }
    Ok(())
}

/// The one name of the file at `path`: the canonical path if the file exists, else the
/// canonical directory (it exists: [`check_writable`] passed) joined with the file name.
fn identity(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (std::fs::canonicalize(dir), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_named_twice_or_unwritable_are_refused() {
        let dir = std::env::temp_dir().join(format!("fogplanes-outputs-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("index.html")).unwrap();
        let (a, b) = (dir.join("a.exr"), dir.join("b.exr"));
        assert!(check_outputs(&[Output::Image(&a), Output::Image(&b), Output::File(&dir.join("t.md"))]).is_ok());
        // Named twice, also through another spelling of the same place.
        let again = dir.join(".").join("a.exr");
        for second in [&a, &again] {
            let e = check_outputs(&[Output::Image(&a), Output::Image(second)]).unwrap_err();
            assert!(e.is_input() && e.to_string().contains("is named twice as an output"), "{e}");
        }
        // A directory where a file goes; an image with an unknown extension.
        let e = check_outputs(&[Output::Image(&a), Output::File(&dir.join("index.html"))]).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        assert!(check_outputs(&[Output::Image(&dir.join("x.jpg"))]).is_err());
        // Nothing was left behind by the checks.
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left, ["index.html"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
