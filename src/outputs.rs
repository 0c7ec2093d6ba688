//! Writing pipeline outputs: colour arrays of one element per pixel become
//! PNGs, any array of primitive elements can become a `.npy`
//! (docs/language.md §4, Outputs). Every file the command writes goes through
//! [`write_atomically`]: it is complete or it does not exist.

use crate::colorbar::Canvas;
use dpp_runtime::interpret::OutputValue;
use dpp_runtime::{Column, FunctorLibrary};
use dpp_tracer::camera::Camera;
use image::DynamicImage;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes the file at `path` whole or not at all. `write` writes a hidden
/// temporary file in the same folder (`.dpp-XXXXXX-NAME`: it ends in the same
/// name, so writers that go by the extension still can); once it has written
/// and synced all of it, the file is renamed over `path` (a rename within one
/// file system is atomic). A failed write (a full disk) removes the temporary
/// file and leaves whatever `path` held before; a process killed while writing
/// (Ctrl-C) can leave only the hidden temporary file, never a truncated file
/// under the final name. `write`'s error is the reason alone: the message
/// returned names `path`.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), String> {
    let cannot =
        |reason: &dyn std::fmt::Display| format!("cannot write {}: {reason}", path.display());
    let name = path
        .file_name()
        .ok_or_else(|| cannot(&"the path names no file"))?
        .to_string_lossy()
        .into_owned();
    let folder = match path.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => folder,
        _ => Path::new("."),
    };
    let suffix = format!("-{name}");
    let mut builder = tempfile::Builder::new();
    builder.prefix(".dpp-").suffix(&suffix);
    // tempfile's own default is owner-only (0600); an output is an ordinary
    // file, readable as the umask allows.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let temporary = builder.tempfile_in(folder).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => {
            cannot(&format!("the folder `{}` does not exist", folder.display()))
        }
        _ => cannot(&e),
    })?;
    write(temporary.path()).map_err(|reason| cannot(&reason))?;
    temporary.as_file().sync_all().map_err(|e| cannot(&e))?;
    temporary.persist(path).map_err(|e| cannot(&e.error))?;
    Ok(())
}

/// How a colour image is finished before it is written.
#[derive(Default)]
pub struct Finish<'a> {
    /// Coverage per pixel: the background becomes transparent.
    pub alpha: Option<&'a [f32]>,
    /// The display colour that missed rays were given (un-blended where transparent).
    pub background: glam::Vec3,
    /// A colour bar: the colour map's display colours and the scalar range.
    pub colorbar: Option<(&'a [glam::Vec3], [f32; 2])>,
}

pub fn write_output(
    name: &str,
    value: &OutputValue,
    path: &Path,
    camera: Option<&Camera>,
    library: &FunctorLibrary,
    finish: &Finish<'_>,
) -> Result<(), String> {
    let OutputValue::Array(column) = value else {
        return Err(format!(
            "output `{name}` is a host scalar; it is printed, not written to a file"
        ));
    };
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match extension.as_str() {
        "png" => write_png(name, column, path, camera, library, finish),
        "npy" => write_npy(name, column, path, library),
        _ => Err(format!(
            "cannot write `{}`: use a .png or .npy file name",
            path.display()
        )),
    }
}

fn write_png(
    name: &str,
    column: &Column,
    path: &Path,
    camera: Option<&Camera>,
    library: &FunctorLibrary,
    finish: &Finish<'_>,
) -> Result<(), String> {
    let Some(camera) = camera else {
        return Err(format!(
            "output `{name}`: a PNG takes its size from the camera, and a run on a volume has none; write it as .npy"
        ));
    };
    let (width, height) = (camera.width, camera.height);
    let pixels = width as usize * height as usize;
    if column.len() != pixels {
        return Err(format!(
            "output `{name}` has {} elements, but a {width}x{height} image has {pixels} pixels; write it as .npy",
            column.len()
        ));
    }
    let to_byte = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let image = match column {
        Column::Vec3(colours) if finish.alpha.is_some() || finish.colorbar.is_some() => {
            let mut canvas = match finish.alpha {
                Some(alpha) => {
                    Canvas::transparent(width, height, colours, alpha, finish.background)
                }
                None => Canvas::from_display(width, height, colours),
            };
            if let Some((lut, range)) = finish.colorbar {
                canvas.draw_colorbar(lut, range);
            }
            let bytes: Vec<u8> = canvas.rgba.into_iter().flatten().collect();
            image::RgbaImage::from_raw(width, height, bytes).map(DynamicImage::from)
        }
        Column::Vec3(colours) => {
            let bytes: Vec<u8> = colours
                .iter()
                .flat_map(|c| c.to_array().map(to_byte))
                .collect();
            image::RgbImage::from_raw(width, height, bytes).map(DynamicImage::from)
        }
        Column::Vec4(colours) => {
            let bytes: Vec<u8> = colours
                .iter()
                .flat_map(|c| c.to_array().map(to_byte))
                .collect();
            image::RgbaImage::from_raw(width, height, bytes).map(DynamicImage::from)
        }
        Column::F32(values) => {
            // A scalar image (depth): finite values scaled to grey, near is bright.
            let finite = values.iter().copied().filter(|v| v.is_finite());
            let (low, high) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
            let span = (high - low).max(f32::MIN_POSITIVE);
            let bytes: Vec<u8> = values
                .iter()
                .map(|v| {
                    if v.is_finite() {
                        to_byte(1.0 - 0.8 * (v - low) / span)
                    } else {
                        0
                    }
                })
                .collect();
            image::GrayImage::from_raw(width, height, bytes).map(DynamicImage::from)
        }
        other => {
            return Err(format!(
            "output `{name}` is an array of {}; a PNG needs vec3, vec4 or f32 (write it as .npy)",
            other.elem_type().name(&library.records)
        ))
        }
    };
    let image = image.ok_or("image buffer of the wrong size")?;
    write_atomically(path, |temporary| {
        let mut file = BufWriter::new(File::create(temporary).map_err(|e| e.to_string())?);
        image
            .write_to(&mut file, image::ImageFormat::Png)
            .map_err(|e| e.to_string())?;
        file.flush().map_err(|e| e.to_string())
    })
}

fn write_npy(
    name: &str,
    column: &Column,
    path: &Path,
    library: &FunctorLibrary,
) -> Result<(), String> {
    use npyz::WriterBuilder;
    if let Column::Record { ty, .. } = column {
        return Err(format!(
            "output `{name}` is an array of records ({}); write one field, like `out t = {name}.t`",
            library.records.get(*ty).name
        ));
    }
    write_atomically(path, |temporary| {
        let io = |e: std::io::Error| e.to_string();
        let mut file = BufWriter::new(File::create(temporary).map_err(io)?);
        let len = column.len() as u64;
        // The buffer is flushed here, not on drop, which would swallow a full disk.
        macro_rules! write_rows {
            ($values:expr, $shape:expr) => {{
                let mut writer = npyz::WriteOptions::new()
                    .default_dtype()
                    .shape($shape)
                    .writer(&mut file)
                    .begin_nd()
                    .map_err(io)?;
                writer.extend($values).map_err(io)?;
                writer.finish().map_err(io)?;
                file.flush().map_err(io)
            }};
        }
        match column {
            Column::Bool(v) => write_rows!(v.iter().map(|b| *b as u8), &[len]),
            Column::U32(v) => write_rows!(v.iter().copied(), &[len]),
            Column::I32(v) => write_rows!(v.iter().copied(), &[len]),
            Column::F32(v) => write_rows!(v.iter().copied(), &[len]),
            Column::Vec2(v) => write_rows!(v.iter().flat_map(|c| c.to_array()), &[len, 2]),
            Column::Vec3(v) => write_rows!(v.iter().flat_map(|c| c.to_array()), &[len, 3]),
            Column::Vec4(v) => write_rows!(v.iter().flat_map(|c| c.to_array()), &[len, 4]),
            Column::Record { .. } => unreachable!("records were refused above"),
        }
    })
}
