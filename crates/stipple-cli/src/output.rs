//! Writing outputs safely: never over an input or another output, never over a device,
//! all or nothing (staged under temporary names and renamed together).

use crate::Result;
use anyhow::{anyhow, Context};
use std::path::{Path, PathBuf};

/// Refuses to write over any input.
/// Refuses an output that is one of the inputs: the same path after resolving symbolic
/// links, or (Unix) the same file under another name (a hard link: same device and inode).
pub fn check_output(out: &Path, inputs: &[&Path]) -> Result<()> {
    not_special(out)?;
    let canon = |p: &Path| std::fs::canonicalize(p).ok();
    let same_file = |a: &Path, b: &Path| -> bool {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
                return x.dev() == y.dev() && x.ino() == y.ino();
            }
        }
        match (canon(a), canon(b)) {
            (Some(x), Some(y)) => x == y,
            _ => false,
        }
    };
    for i in inputs {
        if same_file(out, i) {
            return Err(anyhow!(
                "{}: refusing to overwrite an input file ({})",
                out.display(),
                i.display()
            ));
        }
    }
    Ok(())
}

/// Refuses an output path that exists and is not a regular file (a device such as
/// /dev/full, a directory, a pipe): outputs are written beside it and renamed over it, which
/// would replace the device itself.
pub fn not_special(out: &Path) -> Result<()> {
    let dir = out.parent().filter(|d| !d.as_os_str().is_empty());
    let dir = std::fs::canonicalize(dir.unwrap_or(Path::new("."))).ok();
    if let Some(d) = dir {
        for sys in ["/dev", "/proc", "/sys"] {
            if d.starts_with(sys) {
                return Err(anyhow!(
                    "{}: {sys} holds devices and kernel files, not user files; write the \
                     output somewhere else",
                    out.display()
                ));
            }
        }
    }
    match std::fs::metadata(out) {
        Ok(m) if !m.is_file() => Err(anyhow!(
            "{}: exists and is not a regular file (a device, directory or pipe); outputs are \
             written as regular files only",
            out.display()
        )),
        _ => Ok(()),
    }
}

/// Refuses two outputs of one command at the same place (they would overwrite each other):
/// compared by their absolute path with `.` and `..` resolved in the directory part.
pub fn distinct_outputs(outs: &[&Path]) -> Result<()> {
    let key = |p: &Path| -> PathBuf {
        let dir = p.parent().filter(|d| !d.as_os_str().is_empty());
        let dir = dir
            .map(|d| std::fs::canonicalize(d).unwrap_or_else(|_| d.to_path_buf()))
            .unwrap_or_else(|| std::env::current_dir().unwrap_or_default());
        dir.join(p.file_name().unwrap_or_default())
    };
    for (k, a) in outs.iter().enumerate() {
        for b in &outs[k + 1..] {
            if key(a) == key(b) {
                return Err(anyhow!(
                    "{}: given for two outputs of this command; each output needs its own file",
                    a.display()
                ));
            }
        }
    }
    Ok(())
}

/// The process id of another running stipple process writing `path` (its temporary file
/// `.NAME.PID.stipple-tmp` is beside it and that process is alive), if any.
pub fn other_writer(path: &Path) -> Option<u32> {
    let name = path.file_name()?.to_string_lossy().into_owned();
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    let prefix = format!(".{name}.");
    std::fs::read_dir(dir.unwrap_or(Path::new(".")))
        .ok()?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            let pid = n.strip_prefix(&prefix)?.strip_suffix(".stipple-tmp")?;
            pid.parse::<u32>().ok()
        })
        .find(|&pid| pid != std::process::id() && Path::new(&format!("/proc/{pid}")).exists())
}

/// Outputs of one command, written to temporary files beside their places and renamed into
/// place together by [`Staged::commit`]; dropped uncommitted (an error on the way), the
/// temporary files are removed and no output appears or changes.
#[derive(Default)]
pub struct Staged {
    files: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    pub fn write(
        &mut self,
        path: &Path,
        f: impl FnOnce(&Path) -> std::result::Result<(), stipple_io::IoError>,
    ) -> Result<()> {
        let name = path
            .file_name()
            .ok_or_else(|| anyhow!("{}: the output path has no file name", path.display()))?;
        let mut tmp = std::ffi::OsString::from(".");
        tmp.push(name);
        tmp.push(format!(".{}.stipple-tmp", std::process::id()));
        let tmp = path.with_file_name(tmp);
        not_special(path)?;
        // Our temporary file first, then a look for another live process's: of two
        // processes writing one output at once, at least the later one stops here.
        std::fs::File::create(&tmp).with_context(|| path.display().to_string())?;
        self.files.push((tmp.clone(), path.to_path_buf()));
        if let Some(pid) = other_writer(path) {
            return Err(anyhow!(
                "{}: another stipple process (pid {pid}) is writing it right now; wait for it \
                 to finish or choose another output",
                path.display()
            ));
        }
        f(&tmp).map_err(|e| match e {
            stipple_io::IoError::Io { source, .. } => anyhow!("{}: {source}", path.display()),
            other => anyhow!(
                "{}",
                other
                    .to_string()
                    .replace(&*tmp.to_string_lossy(), &path.to_string_lossy())
            ),
        })
    }

    pub fn commit(mut self) -> Result<()> {
        let files = std::mem::take(&mut self.files);
        for (k, (tmp, path)) in files.iter().enumerate() {
            if let Err(e) = std::fs::rename(tmp, path) {
                for (t, _) in &files[k..] {
                    let _ = std::fs::remove_file(t);
                }
                return Err(anyhow!("{}: {e}", path.display()));
            }
        }
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        for (tmp, _) in &self.files {
            let _ = std::fs::remove_file(tmp);
        }
    }
}
