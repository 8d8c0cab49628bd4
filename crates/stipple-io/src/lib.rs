//! Readers and writers for point clouds (PLY, LAS/LAZ/COPC, XYZ text) and for the renderer's
//! outputs (PNG, NumPy `.npy` depth).
//!
//! Every reader checks what it reads: a truncated file, a header count larger than the file
//! can hold, a wrong magic, a non-finite coordinate or an empty cloud is an [`IoError`] that
//! names the file and the problem. No allocation is sized from a header count before the
//! count was checked against the bytes that are actually there.

pub mod copc;
pub mod e57_io;
pub mod hdr;
pub mod image;
pub mod las_io;
pub mod mesh_io;
pub mod pcd;
pub mod ply;
pub mod volume_io;
pub mod xyz;

use std::io::Read;
use std::path::{Path, PathBuf};
use stipple_core::PointCloud;

#[derive(Debug, thiserror::Error)]
pub enum IoError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
    #[error("{}: {message}", path.display())]
    Unsupported { path: PathBuf, message: String },
}

/// What is wrong with a cloud held in memory (no file name: [`IoError`] adds it when the
/// bytes came from a file).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ParseError(pub String);

impl From<String> for ParseError {
    fn from(m: String) -> ParseError {
        ParseError(m)
    }
}

impl IoError {
    pub fn io(path: &Path, source: std::io::Error) -> IoError {
        IoError::Io {
            path: path.to_owned(),
            source,
        }
    }

    pub fn invalid(path: &Path, message: impl Into<String>) -> IoError {
        IoError::Invalid {
            path: path.to_owned(),
            message: message.into(),
        }
    }
}

/// A file format that stipple reads or writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Ply,
    Las,
    Xyz,
}

/// Reads a point cloud, choosing the reader from the file's first bytes (PLY magic, `LASF`,
/// gzip) and, for headerless text, from its extension. The cloud is validated before it is
/// returned.
pub fn read_cloud(path: &Path) -> Result<PointCloud, IoError> {
    read_cloud_with(path, &ReadOptions::default())
}

/// How [`read_cloud_with`] turns sources that are not point clouds into points.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Volumes (.nrrd, .nii, .nii.gz, .raw): the iso-value whose surface becomes points
    /// (None: Otsu's threshold of the volume, see `stipple_core::volume`).
    pub iso: Option<f64>,
    /// Volumes: a transfer function instead of an iso-surface: every sample it shows becomes
    /// a point with its colour and opacity (see `stipple_core::volume::transfer_points`).
    pub transfer: Option<stipple_core::volume::TransferFunction>,
}

/// A transfer function given as a file (`value r g b opacity` per line) or inline (points
/// between `;`): a path to an existing file is read (at most 1 MiB), anything else parsed.
pub fn transfer_function(
    spec: &str,
    base: Option<&Path>,
) -> Result<stipple_core::volume::TransferFunction, String> {
    let path = match base {
        Some(b) => b.join(spec),
        None => Path::new(spec).to_path_buf(),
    };
    if path.is_file() {
        let len = std::fs::metadata(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .len();
        if len > 1 << 20 {
            return Err(format!(
                "{}: {len} bytes, a transfer function is at most 1 MiB",
                path.display()
            ));
        }
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        return stipple_core::volume::TransferFunction::parse(&text)
            .map_err(|e| format!("{}: {e}", path.display()));
    }
    stipple_core::volume::TransferFunction::parse(spec).map_err(|e| {
        format!("{e} (`{spec}` is not a file, so it was read as the points themselves)")
    })
}

/// Reads a lookup table (see [`stipple_core::lookup`]): TOML, or JSON when the name ends in
/// `.json`; at most 1 MiB. Errors name the file and say what is wrong.
pub fn lookup_table(path: &Path) -> Result<stipple_core::lookup::LookupTable, String> {
    let at = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let meta = std::fs::metadata(path).map_err(|e| at(&e))?;
    if !meta.is_file() {
        return Err(at(&"not a regular file"));
    }
    if meta.len() > 1 << 20 {
        return Err(at(&format!(
            "{} bytes, a lookup table is at most 1 MiB",
            meta.len()
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| at(&e))?;
    let json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let t: stipple_core::lookup::LookupTable = if json {
        serde_json::from_str(&text).map_err(|e| at(&e))?
    } else {
        toml::from_str(&text).map_err(|e| at(&e.to_string().trim_end()))?
    };
    t.validate().map_err(|e| at(&e))?;
    Ok(t)
}

/// The most points an iso-surface may have.
pub const MAX_ISO_POINTS: usize = 1 << 28;

/// [`read_cloud`] with options for volumes.
pub fn read_cloud_with(path: &Path, opt: &ReadOptions) -> Result<PointCloud, IoError> {
    let meta = std::fs::metadata(path).map_err(|e| IoError::io(path, e))?;
    if !meta.is_file() {
        return Err(IoError::invalid(
            path,
            "not a regular file (a device, directory or pipe): stipple reads point files",
        ));
    }
    // PLY and text files are read whole (LAS/LAZ stream into the cloud's columns).
    if !matches!(extension(path).as_str(), "las" | "laz") {
        if let Some(avail) = stipple_core::sys::available_memory() {
            if meta.len() > avail {
                return Err(IoError::invalid(
                    path,
                    format!(
                        "the file is {} MiB, more than the {} MiB of memory available to \
                         read it",
                        meta.len() >> 20,
                        avail >> 20
                    ),
                ));
            }
        }
    }
    let mut head = [0u8; 4];
    let n = {
        let mut f = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
        read_up_to(&mut f, &mut head).map_err(|e| IoError::io(path, e))?
    };
    let head = &head[..n];
    let gz = head.starts_with(&[0x1f, 0x8b]);
    let cloud = if volume_io::is_volume(path) && !head.starts_with(b"ply") {
        let v = volume_io::read_volume(path)?;
        match &opt.transfer {
            Some(tf) => stipple_core::volume::transfer_points(&v, tf, MAX_ISO_POINTS),
            None => {
                let iso = opt.iso.unwrap_or_else(|| stipple_core::volume::otsu(&v));
                stipple_core::volume::iso_points(&v, iso, MAX_ISO_POINTS)
            }
        }
        .map_err(|e| IoError::invalid(path, e.to_string()))?
    } else if head.starts_with(b"ply") || (gz && gz_holds_ply(path)?) {
        ply::read_ply(path)?
    } else if head.starts_with(b"LASF") {
        las_io::read_las(path)?
    } else {
        let ext = extension(path);
        match ext.as_str() {
            "xyz" | "txt" | "csv" | "pts" | "asc" => xyz::read_xyz(path)?,
            "obj" => mesh_io::read_obj(path)?,
            "stl" => mesh_io::read_stl(path)?,
            "pcd" => pcd::read_pcd(path)?,
            "ply" => return Err(IoError::invalid(path, "not a PLY file: the magic `ply` is missing")),
            "las" | "laz" => {
                return Err(IoError::invalid(path, "not a LAS/LAZ file: the signature `LASF` is missing"))
            }
            "e57" => e57_io::read_e57(path)?,
            _ => {
                return Err(IoError::Unsupported {
                    path: path.to_owned(),
                    message: "unrecognised format (supported: .ply, .ply.gz, .las, .laz, .copc.laz, .xyz, .txt, .csv, .pcd, .e57, meshes .obj, .stl, volumes .nrrd, .nii, .nii.gz, .raw)"
                        .into(),
                })
            }
        }
    };
    cloud
        .validate()
        .map_err(|e| IoError::invalid(path, e.to_string()))?;
    Ok(cloud)
}

/// Writes a cloud in the format named by the path's extension (`.ply` binary little endian,
/// `.las`/`.laz`, `.xyz`/`.txt`/`.csv`). The file is written under a temporary name beside
/// the target and renamed into place when complete.
pub fn write_cloud(path: &Path, cloud: &PointCloud) -> Result<(), IoError> {
    let fmt = match extension(path).as_str() {
        "ply" => Format::Ply,
        "las" | "laz" => Format::Las,
        "xyz" | "txt" | "csv" => Format::Xyz,
        other => {
            return Err(IoError::Unsupported {
                path: path.to_owned(),
                message: format!("cannot write `.{other}` files (use .ply, .las, .laz or .xyz)"),
            })
        }
    };
    write_atomically(path, |tmp| match fmt {
        Format::Ply => ply::write_ply(tmp, cloud, ply::Encoding::BinaryLittleEndian),
        Format::Las => las_io::write_las(tmp, cloud, extension(path) == "laz"),
        Format::Xyz => xyz::write_xyz(tmp, cloud),
    })
}

/// Runs `write` on a temporary path beside `path`, then renames it into place; on failure the
/// temporary file is removed and `path` is untouched.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let name = path
        .file_name()
        .ok_or_else(|| IoError::invalid(path, "the output path has no file name"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".{}.tmp", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    match write(&tmp) {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            IoError::io(path, e)
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            // Report the user's path, not the temporary one.
            Err(match e {
                IoError::Io { source, .. } => IoError::io(path, source),
                IoError::Invalid { message, .. } => IoError::invalid(path, message),
                IoError::Unsupported { message, .. } => IoError::Unsupported {
                    path: path.to_owned(),
                    message,
                },
            })
        }
    }
}

/// Lower-case extension, looking through a trailing `.gz`.
pub fn extension(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    match name.rsplit_once('.') {
        Some((_, e)) => e.to_owned(),
        None => String::new(),
    }
}

fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// User text (a file's token, a flag's value) as an error message shows it: escaped, at
/// most 32 characters.
pub fn shown(t: &str) -> String {
    const MAX: usize = 32;
    let mut out: String = t.chars().take(MAX).flat_map(char::escape_debug).collect();
    if t.chars().nth(MAX).is_some() {
        out.push('…');
    }
    out
}

/// Whether a gzip-compressed file starts with the PLY magic once inflated (a `.nii.gz`
/// volume must not be reported as a broken PLY file).
fn gz_holds_ply(path: &Path) -> Result<bool, IoError> {
    let f = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let mut head = [0u8; 3];
    let n = read_up_to(&mut flate2::read::MultiGzDecoder::new(f), &mut head)
        .map_err(|e| IoError::invalid(path, format!("gzip data is corrupt or truncated: {e}")))?;
    Ok(&head[..n] == b"ply")
}

/// Reads a whole file, transparently decompressing gzip.
pub(crate) fn read_maybe_gz(path: &Path) -> Result<Vec<u8>, IoError> {
    let raw = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    if raw.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::with_capacity(raw.len().saturating_mul(4));
        flate2::read::MultiGzDecoder::new(&raw[..])
            .read_to_end(&mut out)
            .map_err(|e| {
                IoError::invalid(path, format!("gzip data is corrupt or truncated: {e}"))
            })?;
        Ok(out)
    } else {
        Ok(raw)
    }
}
