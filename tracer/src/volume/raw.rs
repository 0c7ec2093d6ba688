//! Raw bricks: a file holding nothing but the samples (x fastest), after an
//! optional header of `header_bytes` bytes that is skipped. The file's size must
//! be exactly `header_bytes + x·y·z·(sample size)`.
//!
//! A [`RawSpec`] can be written as text (for command lines):
//! `XxYxZ:TYPE[:le|:be][:header=N][:spacing=SX,SY,SZ]`, e.g. `256x256x128:u16:be`.

use super::{sample_count, Endian, Volume, VolumeError, MAX_SAMPLES};
use glam::{UVec3, Vec3};
use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom};
use std::path::Path;
use std::str::FromStr;

/// The sample type of a raw brick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RawType {
    U8,
    U16,
    F32,
}

impl RawType {
    pub fn size(self) -> u64 {
        match self {
            RawType::U8 => 1,
            RawType::U16 => 2,
            RawType::F32 => 4,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            RawType::U8 => "u8",
            RawType::U16 => "u16",
            RawType::F32 => "f32",
        }
    }
}

impl FromStr for RawType {
    type Err = String;

    fn from_str(s: &str) -> Result<RawType, String> {
        match s.to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" => Ok(RawType::U8),
            "u16" | "uint16" | "ushort" => Ok(RawType::U16),
            "f32" | "float32" | "float" => Ok(RawType::F32),
            _ => Err(format!(
                "unknown sample type '{s}' (expected u8, u16 or f32)"
            )),
        }
    }
}

/// How to read a raw brick: its dimensions, sample type and byte order, how many
/// header bytes to skip, and the spacing to give it (the origin is 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawSpec {
    pub dims: UVec3,
    pub ty: RawType,
    pub endian: Endian,
    pub header_bytes: u64,
    pub spacing: Vec3,
}

impl RawSpec {
    /// Little endian, no header, unit spacing.
    pub fn new(dims: UVec3, ty: RawType) -> RawSpec {
        RawSpec {
            dims,
            ty,
            endian: Endian::Little,
            header_bytes: 0,
            spacing: Vec3::ONE,
        }
    }

    pub fn with_header_bytes(self, header_bytes: u64) -> RawSpec {
        RawSpec {
            header_bytes,
            ..self
        }
    }

    pub fn with_endian(self, endian: Endian) -> RawSpec {
        RawSpec { endian, ..self }
    }

    pub fn with_spacing(self, spacing: Vec3) -> RawSpec {
        RawSpec { spacing, ..self }
    }

    /// Bytes of sample data the brick holds.
    pub fn data_bytes(&self) -> u64 {
        sample_count(self.dims.as_u64vec3().to_array()).saturating_mul(self.ty.size())
    }
}

impl FromStr for RawSpec {
    type Err = VolumeError;

    /// `XxYxZ:TYPE[:le|:be][:header=N][:spacing=SX,SY,SZ]`.
    fn from_str(text: &str) -> Result<RawSpec, VolumeError> {
        let error = |what: String| VolumeError::BadRawSpec {
            spec: text.to_string(),
            what,
        };
        let mut parts = text.split(':');
        let dims: Vec<&str> = parts.next().unwrap_or("").split(['x', 'X']).collect();
        let dims: Vec<u32> = dims
            .iter()
            .map(|d| d.trim().parse::<u32>())
            .collect::<Result<_, _>>()
            .ok()
            .filter(|d: &Vec<u32>| d.len() == 3)
            .ok_or_else(|| {
                error("the dimensions must be three whole numbers, as in 256x256x128".into())
            })?;
        let ty = parts
            .next()
            .ok_or_else(|| error("the sample type (u8, u16 or f32) is missing".into()))?
            .parse()
            .map_err(error)?;
        let mut spec = RawSpec::new(UVec3::new(dims[0], dims[1], dims[2]), ty);
        for part in parts {
            match part.split_once('=') {
                None if part.eq_ignore_ascii_case("le") => spec.endian = Endian::Little,
                None if part.eq_ignore_ascii_case("be") => spec.endian = Endian::Big,
                Some(("header", n)) => {
                    spec.header_bytes = n
                        .parse()
                        .map_err(|_| error(format!("header={n} is not a byte count")))?;
                }
                Some(("spacing", s)) => {
                    let s: Vec<f32> = s
                        .split(',')
                        .map(|v| v.trim().parse::<f32>())
                        .collect::<Result<_, _>>()
                        .ok()
                        .filter(|s: &Vec<f32>| {
                            s.len() == 3 && s.iter().all(|v| v.is_finite() && *v > 0.0)
                        })
                        .ok_or_else(|| {
                            error(format!("spacing={s} must be three positive numbers"))
                        })?;
                    spec.spacing = Vec3::new(s[0], s[1], s[2]);
                }
                _ => {
                    return Err(error(format!(
                        "unknown option '{part}' (expected le, be, header=N or spacing=SX,SY,SZ)"
                    )))
                }
            }
        }
        Ok(spec)
    }
}

/// Reads a raw brick described by `spec` (see the module documentation).
pub fn read_raw(path: &Path, spec: &RawSpec) -> Result<Volume, VolumeError> {
    read_raw_box(path, spec, [UVec3::ZERO, spec.dims])
}

/// The dimensions of the raw brick `spec` describes, after the same checks
/// as [`read_raw`] (the file's size among them), reading no samples.
pub fn raw_dims(path: &Path, spec: &RawSpec) -> Result<UVec3, VolumeError> {
    open_checked(path, spec)?;
    Ok(spec.dims)
}

/// Reads only the samples `[samples[0], samples[1])` (global indices) of the
/// raw brick `spec` describes: one `seek` and `read_exact` per contiguous run
/// of the file (a row of the box, or several rows or slices where the box
/// spans the whole grid along x, or x and y). The volume's `first` is
/// `samples[0]`; the whole file's checks apply.
pub fn read_raw_box(
    path: &Path,
    spec: &RawSpec,
    samples: [UVec3; 2],
) -> Result<Volume, VolumeError> {
    let io_error = |source: io::Error| VolumeError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = open_checked(path, spec)?;
    check_box(path, spec.dims, samples)?;
    let size = spec.ty.size();
    let local = samples[1] - samples[0];
    let mut data = vec![0u8; (sample_count(local.as_u64vec3().to_array()) * size) as usize];
    let mut at = 0usize;
    for (offset, count) in box_runs(spec.dims, samples) {
        let bytes = (count * size) as usize;
        file.seek(SeekFrom::Start(spec.header_bytes + offset * size))
            .map_err(io_error)?;
        file.read_exact(&mut data[at..at + bytes])
            .map_err(io_error)?;
        at += bytes;
    }
    Ok(Volume {
        dims: local,
        spacing: spec.spacing,
        origin: Vec3::ZERO,
        first: samples[0],
        values: decode(&data, spec.ty, spec.endian),
    })
}

/// Fails unless `samples` is a non-empty box inside a `dims` grid.
pub(crate) fn check_box(path: &Path, dims: UVec3, samples: [UVec3; 2]) -> Result<(), VolumeError> {
    let [lo, hi] = samples;
    if lo.cmpge(hi).any() || hi.cmpgt(dims).any() {
        return Err(VolumeError::RawSize {
            path: path.to_path_buf(),
            what: format!(
                "the box of samples [{lo}, {hi}) is empty or not inside the {}×{}×{} grid",
                dims.x, dims.y, dims.z
            ),
        });
    }
    Ok(())
}

/// The contiguous runs of the box `[samples[0], samples[1])` of a `dims` grid
/// stored x fastest, in storage order: `(first sample's index, samples)`.
/// Rows that follow each other in the file are merged into one run.
pub(crate) fn box_runs(dims: UVec3, samples: [UVec3; 2]) -> Vec<(u64, u64)> {
    let [lo, hi] = samples.map(|s| s.as_u64vec3());
    let (nx, ny) = (dims.x as u64, dims.y as u64);
    let mut runs: Vec<(u64, u64)> = Vec::new();
    for k in lo.z..hi.z {
        for j in lo.y..hi.y {
            let start = lo.x + nx * (j + ny * k);
            let count = hi.x - lo.x;
            match runs.last_mut() {
                Some((first, length)) if *first + *length == start => *length += count,
                _ => runs.push((start, count)),
            }
        }
    }
    runs
}

/// Opens the file after checking the spec and that the file's size is exactly
/// what the spec says.
fn open_checked(path: &Path, spec: &RawSpec) -> Result<File, VolumeError> {
    let io_error = |source: io::Error| VolumeError::Io {
        path: path.to_path_buf(),
        source,
    };
    let size_error = |what: String| VolumeError::RawSize {
        path: path.to_path_buf(),
        what,
    };
    let dims = spec.dims.as_u64vec3().to_array();
    if dims.iter().any(|&d| d < 2) {
        return Err(VolumeError::BadDims {
            path: path.to_path_buf(),
            dims: dims.map(|d| d as i64),
        });
    }
    let count = sample_count(dims);
    if count > MAX_SAMPLES {
        return Err(VolumeError::TooManySamples {
            path: path.to_path_buf(),
            dims,
            count,
        });
    }
    if !spec.spacing.is_finite() || spec.spacing.cmple(Vec3::ZERO).any() {
        return Err(size_error(format!(
            "the spacing {} must be positive",
            spec.spacing
        )));
    }
    let file = File::open(path).map_err(io_error)?;
    let file_size = file.metadata().map_err(io_error)?.len();
    let data_bytes = spec.data_bytes();
    let needed = spec.header_bytes.saturating_add(data_bytes);
    let [x, y, z] = dims;
    let brick = format!(
        "{x}×{y}×{z} {} samples ({data_bytes} bytes)",
        spec.ty.name()
    );
    let header = match spec.header_bytes {
        0 => String::new(),
        n => format!(" after a {n}-byte header"),
    };
    if file_size < needed {
        return Err(size_error(format!(
            "the file has {file_size} bytes, but {brick}{header} need {needed}"
        )));
    }
    if file_size > needed {
        let extra = file_size - needed;
        return Err(size_error(format!(
            "the file has {file_size} bytes, {extra} more than the {needed} that {brick}{header} need; \
             if the file starts with a header, give header bytes = {}",
            file_size - data_bytes
        )));
    }
    Ok(file)
}

/// Samples of type `ty` in `endian` order, as f32.
fn decode(data: &[u8], ty: RawType, endian: Endian) -> Vec<f32> {
    let little = endian == Endian::Little;
    match ty {
        RawType::U8 => data.iter().map(|&b| b as f32).collect(),
        RawType::U16 => data
            .chunks_exact(ty.size() as usize)
            .map(|b| {
                let b = [b[0], b[1]];
                (if little {
                    u16::from_le_bytes(b)
                } else {
                    u16::from_be_bytes(b)
                }) as f32
            })
            .collect(),
        RawType::F32 => data
            .chunks_exact(ty.size() as usize)
            .map(|b| {
                let b = [b[0], b[1], b[2], b[3]];
                if little {
                    f32::from_le_bytes(b)
                } else {
                    f32::from_be_bytes(b)
                }
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn file(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let path = dir.path().join(name);
        fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn reads_each_type_and_byte_order() {
        let dir = tempfile::tempdir().unwrap();
        let dims = UVec3::new(3, 2, 2);
        let u8s: Vec<u8> = (0..12).map(|v| v * 7).collect();
        let path = file(&dir, "a.raw", &u8s);
        let volume = Volume::load(&path, Some(RawSpec::new(dims, RawType::U8))).unwrap();
        assert_eq!(volume.dims, dims);
        assert_eq!(
            volume.values,
            u8s.iter().map(|&v| v as f32).collect::<Vec<_>>()
        );
        assert_eq!(volume.value(2, 1, 1), 77.0);

        let u16s: Vec<u16> = (0..12).map(|v| v * 5000 + 1).collect();
        for endian in [Endian::Little, Endian::Big] {
            let bytes: Vec<u8> = u16s
                .iter()
                .flat_map(|v| match endian {
                    Endian::Little => v.to_le_bytes(),
                    Endian::Big => v.to_be_bytes(),
                })
                .collect();
            let path = file(&dir, "b.raw", &bytes);
            let spec = RawSpec::new(dims, RawType::U16).with_endian(endian);
            let volume = read_raw(&path, &spec).unwrap();
            assert_eq!(
                volume.values,
                u16s.iter().map(|&v| v as f32).collect::<Vec<_>>()
            );
        }

        let f32s: Vec<f32> = (0..12).map(|v| v as f32 * -0.5).collect();
        let mut bytes = b"HEADER!".to_vec();
        bytes.extend(f32s.iter().flat_map(|v| v.to_be_bytes()));
        let path = file(&dir, "c.raw", &bytes);
        let spec = RawSpec::new(dims, RawType::F32)
            .with_endian(Endian::Big)
            .with_header_bytes(7)
            .with_spacing(Vec3::new(1.0, 2.0, 3.0));
        let volume = read_raw(&path, &spec).unwrap();
        assert_eq!(volume.values, f32s);
        assert_eq!(volume.spacing, Vec3::new(1.0, 2.0, 3.0));
    }

    #[test]
    fn size_mismatches_are_errors_naming_both_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let spec = RawSpec::new(UVec3::new(4, 4, 4), RawType::U16);
        let path = file(&dir, "short.raw", &[0; 127]);
        let message = read_raw(&path, &spec).unwrap_err().to_string();
        assert!(message.contains("short.raw"), "{message}");
        assert!(
            message.contains("127 bytes") && message.contains("need 128"),
            "{message}"
        );

        let path = file(&dir, "long.raw", &[0; 140]);
        let message = read_raw(&path, &spec).unwrap_err().to_string();
        assert!(
            message.contains("140 bytes, 12 more than the 128"),
            "{message}"
        );
        assert!(message.contains("header bytes = 12"), "{message}");
        assert!(read_raw(&path, &spec.with_header_bytes(12)).is_ok());
        let message = read_raw(&path, &spec.with_header_bytes(20))
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("after a 20-byte header need 148"),
            "{message}"
        );

        let flat = RawSpec::new(UVec3::new(4, 1, 4), RawType::U8);
        assert!(matches!(
            read_raw(&path, &flat),
            Err(VolumeError::BadDims { .. })
        ));
        let huge = RawSpec::new(UVec3::splat(100_000), RawType::U8);
        assert!(matches!(
            read_raw(&path, &huge),
            Err(VolumeError::TooManySamples { .. })
        ));
        let missing = read_raw(&dir.path().join("missing.raw"), &spec).unwrap_err();
        assert!(matches!(missing, VolumeError::Io { .. }));
        assert!(missing.to_string().contains("missing.raw"));
    }

    #[test]
    fn specs_parse_from_text() {
        let spec: RawSpec = "256x128x64:u16:be:header=16:spacing=1,1,2.5"
            .parse()
            .unwrap();
        assert_eq!(
            spec,
            RawSpec::new(UVec3::new(256, 128, 64), RawType::U16)
                .with_endian(Endian::Big)
                .with_header_bytes(16)
                .with_spacing(Vec3::new(1.0, 1.0, 2.5))
        );
        assert_eq!("8X8X8:F32".parse::<RawSpec>().unwrap().ty, RawType::F32);
        for bad in [
            "8x8:u8",
            "8x8x8",
            "8x8x8:u32",
            "8x8x8:u8:header=-1",
            "8x8x8:u8:zip",
            "axbxc:u8",
        ] {
            let error = bad.parse::<RawSpec>().unwrap_err();
            assert!(error.to_string().contains(bad), "{error}");
        }
    }

    #[test]
    fn a_box_read_is_the_same_sub_box_of_the_whole_read() {
        use crate::volume::kd_bricks;
        let dir = tempfile::tempdir().unwrap();
        let dims = UVec3::new(7, 5, 6);
        let values: Vec<u16> = (0..7 * 5 * 6).map(|v| v * 301 + 7).collect();
        let mut bytes = b"HDR".to_vec();
        bytes.extend(values.iter().flat_map(|v| v.to_be_bytes()));
        let path = file(&dir, "box.raw", &bytes);
        let spec = RawSpec::new(dims, RawType::U16)
            .with_endian(Endian::Big)
            .with_header_bytes(3)
            .with_spacing(Vec3::new(0.5, 1.0, 2.0));
        let whole = read_raw(&path, &spec).unwrap();
        assert_eq!(Volume::read_dims(&path, Some(spec)).unwrap(), dims);
        for parts in 1..=6 {
            for brick in kd_bricks(dims - UVec3::ONE, parts) {
                let part = Volume::load_brick(&path, Some(spec), &brick).unwrap();
                assert_eq!(part, whole.sub_box(brick.samples[0], brick.samples[1]));
            }
        }
        // Runs merge where the box spans whole rows and slices.
        assert_eq!(box_runs(dims, [UVec3::ZERO, dims]), [(0, 7 * 5 * 6)]);
        assert_eq!(
            box_runs(dims, [UVec3::new(0, 0, 2), UVec3::new(7, 5, 4)]),
            [(70, 70)]
        );
        assert_eq!(
            box_runs(dims, [UVec3::new(1, 3, 0), UVec3::new(3, 5, 1)]),
            [(22, 2), (29, 2)]
        );
        assert!(read_raw_box(&path, &spec, [UVec3::ZERO, UVec3::new(8, 5, 6)]).is_err());
        assert!(read_raw_box(&path, &spec, [UVec3::ONE, UVec3::ONE]).is_err());
    }
}
