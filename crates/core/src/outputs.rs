//! Every output of a command checked before any work: each can be written, none is a
//! directory, no file is named twice (the second write would replace the first, as
//! `reference -o x.exr --stderr-image x.exr` once lost its reference), and none is one of the
//! command's inputs (`compare IMG REF --ref-stderr SE --z-image IMG` once wrote the z-image over
//! the image it had just read, and `merge a.npz b.npz -o a.npz` over a part).

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
    /// A directory the command writes its files into (a checkpoint), checked where it is
    /// opened: here it is only kept apart from the other outputs and the inputs, since
    /// `render -o x.exr --checkpoint x.exr` made the directory x.exr and failed to move the
    /// finished image onto it, after the whole render.
    Directory(&'a Path),
}

impl Output<'_> {
    pub fn path(&self) -> &Path {
        match self {
            Output::Image(p) | Output::File(p) | Output::Directory(p) => p,
        }
    }
}

/// Checks every output before any work: writable ([`check_writable`]), an image's format
/// known, each file named once, and none of them one of `inputs`, the files the command reads
/// (two names of one file count as one: `./x.exr` and `x.exr`, or a link and its target).
pub fn check_outputs(outputs: &[Output<'_>], inputs: &[&Path]) -> Result<()> {
    let inputs: Vec<(Identity, &Path)> = inputs.iter().map(|&p| (identity(p), p)).collect();
    let mut seen: Vec<(Identity, &Path)> = Vec::with_capacity(outputs.len());
    for output in outputs {
        match output {
            Output::Image(p) => check_image_output(p)?,
            Output::File(p) => check_writable(p)?,
            Output::Directory(_) => {}
        }
        let path = output.path();
        let id = identity(path);
        if let Some((_, first)) = seen.iter().find(|(other, _)| *other == id) {
            let also = if *first == path { String::new() } else { format!(" (also as {})", first.display()) };
            return Err(Error::bad_input(path, format!("is named twice as an output{also}")));
        }
        if let Some((_, input)) = inputs.iter().find(|(other, _)| *other == id) {
            let also = if *input == path { String::new() } else { format!(" (as {})", input.display()) };
            return Err(Error::bad_input(
                path,
                format!("is an input of this command{also}: writing it would lose it; name another output"),
            ));
        }
        seen.push((id, path));
    }
    Ok(())
}

/// What makes two paths one file: the device and inode of a file that exists (so that a link,
/// hard or symbolic, and its target are one), else the canonical directory (it exists:
/// [`check_writable`] passed) joined with the file name.
#[derive(Debug, PartialEq, Eq)]
enum Identity {
    #[cfg(unix)]
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Identity {
    #[cfg(unix)]
    if let Ok(m) = std::fs::metadata(path) {
        use std::os::unix::fs::MetadataExt;
        return Identity::Inode(m.dev(), m.ino());
    }
    if let Ok(p) = std::fs::canonicalize(path) {
        return Identity::Path(p);
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    Identity::Path(match (std::fs::canonicalize(dir), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    })
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
        assert!(check_outputs(&[Output::Image(&a), Output::Image(&b), Output::File(&dir.join("t.md"))], &[]).is_ok());
        // Named twice, also through another spelling of the same place.
        let again = dir.join(".").join("a.exr");
        for second in [&a, &again] {
            let e = check_outputs(&[Output::Image(&a), Output::Image(second)], &[]).unwrap_err();
            assert!(e.is_input() && e.to_string().contains("is named twice as an output"), "{e}");
        }
        // A directory where a file goes; an image with an unknown extension.
        let e = check_outputs(&[Output::Image(&a), Output::File(&dir.join("index.html"))], &[]).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        assert!(check_outputs(&[Output::Image(&dir.join("x.jpg"))], &[]).is_err());
        // An output that is one of the inputs, under any of its names: the same spelling, a
        // `./` spelling, a symbolic link to it, a hard link to it.
        let input = dir.join("in.exr");
        std::fs::write(&input, b"an input").unwrap();
        let (soft, hard) = (dir.join("soft.exr"), dir.join("hard.exr"));
        std::os::unix::fs::symlink(&input, &soft).unwrap();
        std::fs::hard_link(&input, &hard).unwrap();
        for (output, input) in [
            (&input, &input),
            (&dir.join(".").join("in.exr"), &input),
            (&soft, &input),
            (&input, &soft),
            (&hard, &input),
        ] {
            let e = check_outputs(&[Output::Image(&a), Output::Image(output)], &[&b, input]).unwrap_err();
            assert!(e.is_input() && e.to_string().contains("is an input of this command"), "{e}");
        }
        assert!(check_outputs(&[Output::Image(&a)], &[&input, &soft]).is_ok());
        for f in [&input, &soft, &hard] {
            std::fs::remove_file(f).unwrap();
        }
        // Nothing was left behind by the checks.
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left, ["index.html"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
