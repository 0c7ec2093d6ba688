//! NIfTI-1 files: a fixed 348-byte header followed (after optional extensions,
//! at `vox_offset`) by the samples, x fastest; `.nii` (one file, magic `n+1`),
//! `.hdr` + `.img` pairs (magic `ni1`), any of them gzip-compressed.
//!
//! What is read: `dim[1..=3]` (a 4-D or higher file gives its first volume),
//! `pixdim[1..=3]` as the spacing (absolute values; 0 means 1), the origin from
//! the sform offsets (`srow_*[3]`) when `sform_code > 0`, else the qform offsets
//! when `qform_code > 0`, else 0, the data type, and `scl_slope`/`scl_inter`
//! (applied when the slope is finite and not 0). Rotations in the qform/sform
//! are not applied: the volume stays aligned with its voxel axes. The byte order
//! is the one in which `sizeof_hdr` reads 348; gzip is detected from the data
//! (its magic bytes), not the name.
//!
//! Written by hand rather than with the `nifti` crate: the format is one fixed
//! header, and the crate (ndarray by default, byteordered, num-derive, …) would
//! add a dozen crates to the tree and its errors do not name the file.

use super::{sample_count, Endian, Volume, VolumeError, MAX_SAMPLES};
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;
use glam::{UVec3, Vec3};
use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Size of a NIfTI-1 header.
pub const HEADER_SIZE: usize = 348;
/// `vox_offset` of a single file without extensions: the header and the 4-byte
/// extension flag.
pub const DEFAULT_VOX_OFFSET: usize = 352;
const MAGIC_SINGLE: [u8; 4] = *b"n+1\0";
const MAGIC_PAIR: [u8; 4] = *b"ni1\0";

/// A sample type of a NIfTI file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Datatype {
    U8,
    I8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Datatype {
    /// The NIfTI `datatype` code, or the name of an unsupported one.
    pub fn from_code(code: i16) -> Result<Datatype, &'static str> {
        Ok(match code {
            2 => Datatype::U8,
            256 => Datatype::I8,
            4 => Datatype::I16,
            512 => Datatype::U16,
            8 => Datatype::I32,
            768 => Datatype::U32,
            1024 => Datatype::I64,
            1280 => Datatype::U64,
            16 => Datatype::F32,
            64 => Datatype::F64,
            0 => return Err("unknown"),
            1 => return Err("binary"),
            32 => return Err("complex64"),
            128 => return Err("rgb24"),
            1536 => return Err("float128"),
            1792 => return Err("complex128"),
            2048 => return Err("complex256"),
            2304 => return Err("rgba32"),
            _ => return Err("not a NIfTI data type"),
        })
    }

    pub fn code(self) -> i16 {
        match self {
            Datatype::U8 => 2,
            Datatype::I8 => 256,
            Datatype::I16 => 4,
            Datatype::U16 => 512,
            Datatype::I32 => 8,
            Datatype::U32 => 768,
            Datatype::I64 => 1024,
            Datatype::U64 => 1280,
            Datatype::F32 => 16,
            Datatype::F64 => 64,
        }
    }

    pub fn size(self) -> usize {
        match self {
            Datatype::U8 | Datatype::I8 => 1,
            Datatype::I16 | Datatype::U16 => 2,
            Datatype::I32 | Datatype::U32 | Datatype::F32 => 4,
            Datatype::I64 | Datatype::U64 | Datatype::F64 => 8,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Datatype::U8 => "u8",
            Datatype::I8 => "i8",
            Datatype::I16 => "i16",
            Datatype::U16 => "u16",
            Datatype::I32 => "i32",
            Datatype::U32 => "u32",
            Datatype::I64 => "i64",
            Datatype::U64 => "u64",
            Datatype::F32 => "f32",
            Datatype::F64 => "f64",
        }
    }
}

/// The header fields dpp reads or writes (everything else is written as 0).
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub dim: [i16; 8],
    pub datatype: i16,
    pub bitpix: i16,
    pub pixdim: [f32; 8],
    pub vox_offset: f32,
    pub scl_slope: f32,
    pub scl_inter: f32,
    pub qform_code: i16,
    pub sform_code: i16,
    /// quatern_b, quatern_c, quatern_d.
    pub quatern: [f32; 3],
    pub qoffset: [f32; 3],
    /// srow_x, srow_y, srow_z.
    pub srow: [[f32; 4]; 3],
    pub magic: [u8; 4],
}

impl Header {
    /// A single-file (`n+1`) header for a 3-D volume of `datatype` samples with no
    /// extensions, unit spacing, no orientation and no scaling.
    pub fn new(dims: [i16; 3], datatype: Datatype) -> Header {
        Header {
            dim: [3, dims[0], dims[1], dims[2], 1, 1, 1, 1],
            datatype: datatype.code(),
            bitpix: 8 * datatype.size() as i16,
            pixdim: [1.0; 8],
            vox_offset: DEFAULT_VOX_OFFSET as f32,
            scl_slope: 0.0,
            scl_inter: 0.0,
            qform_code: 0,
            sform_code: 0,
            quatern: [0.0; 3],
            qoffset: [0.0; 3],
            srow: [[0.0; 4]; 3],
            magic: MAGIC_SINGLE,
        }
    }

    /// The 348 header bytes in `endian` order (offsets from the NIfTI-1 standard,
    /// `nifti1.h`).
    pub fn to_bytes(&self, endian: Endian) -> [u8; HEADER_SIZE] {
        let mut bytes = [0u8; HEADER_SIZE];
        let mut put = |offset: usize, value: &[u8]| {
            bytes[offset..offset + value.len()].copy_from_slice(value);
        };
        let i16b = |v: i16| match endian {
            Endian::Little => v.to_le_bytes(),
            Endian::Big => v.to_be_bytes(),
        };
        let f32b = |v: f32| match endian {
            Endian::Little => v.to_le_bytes(),
            Endian::Big => v.to_be_bytes(),
        };
        let size = match endian {
            Endian::Little => (HEADER_SIZE as i32).to_le_bytes(),
            Endian::Big => (HEADER_SIZE as i32).to_be_bytes(),
        };
        put(0, &size);
        put(38, b"r"); // regular
        for (n, &d) in self.dim.iter().enumerate() {
            put(40 + 2 * n, &i16b(d));
        }
        put(70, &i16b(self.datatype));
        put(72, &i16b(self.bitpix));
        for (n, &p) in self.pixdim.iter().enumerate() {
            put(76 + 4 * n, &f32b(p));
        }
        put(108, &f32b(self.vox_offset));
        put(112, &f32b(self.scl_slope));
        put(116, &f32b(self.scl_inter));
        put(148, b"dpp");
        put(252, &i16b(self.qform_code));
        put(254, &i16b(self.sform_code));
        for (n, &q) in self.quatern.iter().chain(&self.qoffset).enumerate() {
            put(256 + 4 * n, &f32b(q));
        }
        for (n, &s) in self.srow.iter().flatten().enumerate() {
            put(280 + 4 * n, &f32b(s));
        }
        put(344, &self.magic);
        bytes
    }

    /// Parses the 348 header bytes, detecting the byte order from `sizeof_hdr`;
    /// checks the size and the magic only.
    fn parse(bytes: &[u8; HEADER_SIZE], path: &Path) -> Result<(Header, Endian), VolumeError> {
        let word = |offset: usize| -> [u8; 4] { bytes[offset..offset + 4].try_into().unwrap() };
        let (le, be) = (i32::from_le_bytes(word(0)), i32::from_be_bytes(word(0)));
        let endian = if le == HEADER_SIZE as i32 {
            Endian::Little
        } else if be == HEADER_SIZE as i32 {
            Endian::Big
        } else if le == 540 || be == 540 {
            return Err(bad_magic(
                path,
                "this is a NIfTI-2 file (sizeof_hdr 540), which is not supported; convert it to NIfTI-1".into(),
            ));
        } else {
            return Err(bad_magic(
                path,
                format!("sizeof_hdr is {le} (little endian) or {be} (big endian), expected 348"),
            ));
        };
        let magic: [u8; 4] = word(344);
        if magic != MAGIC_SINGLE && magic != MAGIC_PAIR {
            let what = if magic == [0; 4] {
                "there is no magic string (an ANALYZE 7.5 header?); expected \"n+1\" or \"ni1\""
                    .into()
            } else {
                format!(
                    "the magic string is \"{}\", expected \"n+1\" or \"ni1\"",
                    magic.escape_ascii()
                )
            };
            return Err(bad_magic(path, what));
        }
        let i16at = |offset: usize| {
            let b = [bytes[offset], bytes[offset + 1]];
            match endian {
                Endian::Little => i16::from_le_bytes(b),
                Endian::Big => i16::from_be_bytes(b),
            }
        };
        let f32at = |offset: usize| match endian {
            Endian::Little => f32::from_le_bytes(word(offset)),
            Endian::Big => f32::from_be_bytes(word(offset)),
        };
        let header = Header {
            dim: std::array::from_fn(|n| i16at(40 + 2 * n)),
            datatype: i16at(70),
            bitpix: i16at(72),
            pixdim: std::array::from_fn(|n| f32at(76 + 4 * n)),
            vox_offset: f32at(108),
            scl_slope: f32at(112),
            scl_inter: f32at(116),
            qform_code: i16at(252),
            sform_code: i16at(254),
            quatern: std::array::from_fn(|n| f32at(256 + 4 * n)),
            qoffset: std::array::from_fn(|n| f32at(268 + 4 * n)),
            srow: std::array::from_fn(|r| std::array::from_fn(|c| f32at(280 + 16 * r + 4 * c))),
            magic,
        };
        Ok((header, endian))
    }
}

fn bad_magic(path: &Path, what: String) -> VolumeError {
    VolumeError::BadMagic {
        path: path.to_path_buf(),
        what,
    }
}

fn bad_header(path: &Path, what: String) -> VolumeError {
    VolumeError::BadHeader {
        path: path.to_path_buf(),
        what,
    }
}

fn io_error(path: &Path) -> impl FnOnce(io::Error) -> VolumeError + '_ {
    move |source| VolumeError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Opens `path`, transparently decompressing it when it starts with gzip's magic.
fn open(path: &Path) -> Result<Box<dyn Read>, VolumeError> {
    let mut file = BufReader::new(File::open(path).map_err(io_error(path))?);
    let gzipped = file
        .fill_buf()
        .map_err(io_error(path))?
        .starts_with(&[0x1f, 0x8b]);
    Ok(if gzipped {
        Box::new(MultiGzDecoder::new(file))
    } else {
        Box::new(file)
    })
}

/// Reads up to `limit` bytes (fewer only at the end of the data).
fn read_up_to(reader: &mut dyn Read, limit: u64, path: &Path) -> Result<Vec<u8>, VolumeError> {
    let mut bytes = Vec::new();
    reader
        .take(limit)
        .read_to_end(&mut bytes)
        .map_err(io_error(path))?;
    Ok(bytes)
}

/// Skips up to `count` bytes, returning how many there were.
fn skip(reader: &mut dyn Read, count: u64, path: &Path) -> Result<u64, VolumeError> {
    io::copy(&mut reader.take(count), &mut io::sink()).map_err(io_error(path))
}

/// The `.img` (or `.img.gz`) beside a `.hdr`.
fn image_path(path: &Path) -> PathBuf {
    let name = path.to_string_lossy();
    let lower = name.to_ascii_lowercase();
    let stem = ["hdr.gz", "hdr", "nii.gz", "nii"]
        .iter()
        .find(|ext| lower.ends_with(*ext))
        .map_or(&name[..], |ext| &name[..name.len() - ext.len()]);
    let plain = PathBuf::from(format!("{stem}img"));
    let gzipped = PathBuf::from(format!("{stem}img.gz"));
    if !plain.exists() && gzipped.exists() {
        gzipped
    } else {
        plain
    }
}

/// Reads a NIfTI-1 volume (see the module documentation for what is read).
pub fn read_nifti(path: &Path) -> Result<Volume, VolumeError> {
    let (header, endian, layout, header_reader) = read_header(path)?;
    // The samples: after the header in the same file, or in the `.img` file.
    let data_path = samples_path(&header, path);
    let (mut data_reader, already_read) = if header.magic == MAGIC_SINGLE {
        (header_reader, HEADER_SIZE as u64)
    } else {
        (open(&data_path)?, 0)
    };
    let skipped = skip(
        &mut *data_reader,
        layout.vox_offset - already_read,
        &data_path,
    )?;
    let data = read_up_to(&mut *data_reader, layout.data_bytes, &data_path)?;
    if (data.len() as u64) < layout.data_bytes {
        let actual = already_read + skipped + data.len() as u64;
        return Err(truncated_samples(&layout, data_path, actual));
    }

    let (slope, inter) = (header.scl_slope as f64, header.scl_inter as f64);
    let values = if slope.is_finite() && slope != 0.0 {
        let inter = if inter.is_finite() { inter } else { 0.0 };
        decode(&data, layout.datatype, endian, |v| {
            (v * slope + inter) as f32
        })
    } else {
        decode(&data, layout.datatype, endian, |v| v as f32)
    };
    let [x, y, z] = layout.dims.map(|d| d as u32);
    Ok(Volume {
        dims: UVec3::new(x, y, z),
        spacing: layout.spacing,
        origin: layout.origin,
        first: UVec3::ZERO,
        values,
    })
}

/// The file that holds the samples: the header's own (`.nii`), or the `.img`
/// beside it.
fn samples_path(header: &Header, path: &Path) -> PathBuf {
    if header.magic == MAGIC_SINGLE {
        path.to_path_buf()
    } else {
        image_path(path)
    }
}

/// The error for a samples file that ends after `actual` of the bytes
/// `layout` needs.
fn truncated_samples(layout: &Layout, data_path: PathBuf, actual: u64) -> VolumeError {
    let [x, y, z] = layout.dims;
    VolumeError::Truncated {
        path: data_path,
        what: format!(
            "{x}×{y}×{z} {} samples from byte {}",
            layout.datatype.name(),
            layout.vox_offset
        ),
        needed: layout.vox_offset + layout.data_bytes,
        actual,
    }
}

/// The header of a NIfTI-1 file, checked, with the reader positioned after it.
fn read_header(path: &Path) -> Result<(Header, Endian, Layout, Box<dyn Read>), VolumeError> {
    let mut reader = open(path)?;
    let bytes = read_up_to(&mut reader, HEADER_SIZE as u64, path)?;
    let Ok(bytes) = <[u8; HEADER_SIZE]>::try_from(bytes.as_slice()) else {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            what: "the NIfTI-1 header".into(),
            needed: HEADER_SIZE as u64,
            actual: bytes.len() as u64,
        });
    };
    let (header, endian) = Header::parse(&bytes, path)?;
    let layout = Layout::of(&header, path)?;
    if header.magic == MAGIC_SINGLE && layout.vox_offset < HEADER_SIZE as u64 {
        return Err(bad_header(
            path,
            format!(
                "vox_offset {} lies inside the {HEADER_SIZE}-byte header",
                layout.vox_offset
            ),
        ));
    }
    Ok((header, endian, layout, reader))
}

/// The sample dimensions of a NIfTI-1 file, from its header alone (the
/// header is checked as [`read_nifti`] checks it; the samples are not read).
pub fn nifti_dims(path: &Path) -> Result<UVec3, VolumeError> {
    let (_, _, layout, _) = read_header(path)?;
    let [x, y, z] = layout.dims.map(|d| d as u32);
    Ok(UVec3::new(x, y, z))
}

/// Reads only the samples `[samples[0], samples[1])` (global indices) of a
/// NIfTI-1 volume, with `first = samples[0]`; otherwise as [`read_nifti`].
///
/// An uncompressed file is read by seeking: one `seek` and `read_exact` per
/// contiguous run of the box (a row, or more where the box spans whole rows
/// or slices). A gzipped file cannot seek: it is decompressed as a stream up
/// to the box's last sample, keeping only the box's samples, so every reader
/// of a brick pays for decompressing the file up to its brick (the whole file
/// for the last one) while its memory stays the size of its brick.
pub fn read_nifti_box(path: &Path, samples: [UVec3; 2]) -> Result<Volume, VolumeError> {
    let (header, endian, layout, header_reader) = read_header(path)?;
    let [x, y, z] = layout.dims.map(|d| d as u32);
    let dims = UVec3::new(x, y, z);
    super::raw::check_box(path, dims, samples)?;
    let single = header.magic == MAGIC_SINGLE;
    let data_path = samples_path(&header, path);
    let size = layout.datatype.size() as u64;
    let local = samples[1] - samples[0];
    let mut data = vec![0u8; (sample_count(local.as_u64vec3().to_array()) * size) as usize];
    let runs = super::raw::box_runs(dims, samples);
    let truncated = |actual: u64| truncated_samples(&layout, data_path.clone(), actual);
    let gzipped = {
        let mut file = BufReader::new(File::open(&data_path).map_err(io_error(&data_path))?);
        file.fill_buf()
            .map_err(io_error(&data_path))?
            .starts_with(&[0x1f, 0x8b])
    };
    if !gzipped {
        let mut file = File::open(&data_path).map_err(io_error(&data_path))?;
        let file_size = file.metadata().map_err(io_error(&data_path))?.len();
        if file_size < layout.vox_offset + layout.data_bytes {
            return Err(truncated(file_size));
        }
        let mut at = 0usize;
        for (offset, count) in runs {
            let bytes = (count * size) as usize;
            file.seek(SeekFrom::Start(layout.vox_offset + offset * size))
                .map_err(io_error(&data_path))?;
            file.read_exact(&mut data[at..at + bytes])
                .map_err(io_error(&data_path))?;
            at += bytes;
        }
    } else {
        // A stream: skip to each run and read it, in storage order.
        let (mut reader, mut position) = if single {
            (header_reader, HEADER_SIZE as u64)
        } else {
            (open(&data_path)?, 0)
        };
        let mut at = 0usize;
        for (offset, count) in runs {
            let start = layout.vox_offset + offset * size;
            let skipped = skip(&mut *reader, start - position, &data_path)?;
            if skipped < start - position {
                return Err(truncated(position + skipped));
            }
            let bytes = (count * size) as usize;
            let read = read_up_to(&mut *reader, bytes as u64, &data_path)?;
            if read.len() < bytes {
                return Err(truncated(start + read.len() as u64));
            }
            data[at..at + bytes].copy_from_slice(&read);
            at += bytes;
            position = start + bytes as u64;
        }
    }
    Ok(Volume {
        dims: local,
        spacing: layout.spacing,
        origin: layout.origin,
        first: samples[0],
        values: decode_scaled(&data, &header, &layout, endian),
    })
}

/// The samples decoded and scaled by `scl_slope` and `scl_inter` (when the
/// slope is finite and not 0).
fn decode_scaled(data: &[u8], header: &Header, layout: &Layout, endian: Endian) -> Vec<f32> {
    let (slope, inter) = (header.scl_slope as f64, header.scl_inter as f64);
    if slope.is_finite() && slope != 0.0 {
        let inter = if inter.is_finite() { inter } else { 0.0 };
        decode(data, layout.datatype, endian, |v| {
            (v * slope + inter) as f32
        })
    } else {
        decode(data, layout.datatype, endian, |v| v as f32)
    }
}

/// Where the first volume's samples are and what they are, checked.
struct Layout {
    dims: [u64; 3],
    datatype: Datatype,
    vox_offset: u64,
    data_bytes: u64,
    spacing: Vec3,
    origin: Vec3,
}

impl Layout {
    fn of(header: &Header, path: &Path) -> Result<Layout, VolumeError> {
        let rank = header.dim[0];
        if !(1..=7).contains(&rank) {
            return Err(bad_header(
                path,
                format!("dim[0] (the number of dimensions) is {rank}, expected 1 to 7"),
            ));
        }
        let dim = |n: usize| if n <= rank as usize { header.dim[n] } else { 1 };
        let dims = [1, 2, 3].map(|n| dim(n) as i64);
        if dims.iter().any(|&d| d < 2) {
            return Err(VolumeError::BadDims {
                path: path.to_path_buf(),
                dims,
            });
        }
        if let Some(n) = (4..=rank as usize).find(|&n| dim(n) < 1) {
            return Err(bad_header(
                path,
                format!("dim[{n}] is {}, expected at least 1", dim(n)),
            ));
        }
        let dims = dims.map(|d| d as u64);
        let count = sample_count(dims);
        if count > MAX_SAMPLES {
            return Err(VolumeError::TooManySamples {
                path: path.to_path_buf(),
                dims,
                count,
            });
        }
        let datatype = Datatype::from_code(header.datatype).map_err(|name| {
            VolumeError::UnsupportedDatatype {
                path: path.to_path_buf(),
                code: header.datatype,
                name,
            }
        })?;
        let offset = header.vox_offset;
        if !(offset.is_finite() && offset >= 0.0 && offset.fract() == 0.0 && offset < 1e12) {
            return Err(bad_header(
                path,
                format!("vox_offset {offset} is not a byte offset"),
            ));
        }
        let spacing = Vec3::from_array(std::array::from_fn(|n| {
            let p = header.pixdim[n + 1].abs();
            if p.is_finite() && p > 0.0 {
                p
            } else {
                1.0
            }
        }));
        let (origin, what) = if header.sform_code > 0 {
            (header.srow.map(|row| row[3]), "sform offset (srow_*[3])")
        } else if header.qform_code > 0 {
            (header.qoffset, "qform offset (qoffset_*)")
        } else {
            ([0.0; 3], "")
        };
        if origin.iter().any(|o| !o.is_finite()) {
            return Err(bad_header(
                path,
                format!("the {what} {origin:?} is not finite"),
            ));
        }
        Ok(Layout {
            dims,
            datatype,
            vox_offset: offset as u64,
            data_bytes: count * datatype.size() as u64,
            spacing,
            origin: Vec3::from_array(origin),
        })
    }
}

/// Samples of `datatype` in `endian` order, each converted to f64 and passed
/// through `map`.
fn decode(data: &[u8], datatype: Datatype, endian: Endian, map: impl Fn(f64) -> f32) -> Vec<f32> {
    macro_rules! convert {
        ($ty:ty, $size:expr) => {
            data.chunks_exact($size)
                .map(|b| {
                    let b = b.try_into().unwrap();
                    map((match endian {
                        Endian::Little => <$ty>::from_le_bytes(b),
                        Endian::Big => <$ty>::from_be_bytes(b),
                    }) as f64)
                })
                .collect()
        };
    }
    match datatype {
        Datatype::U8 => data.iter().map(|&b| map(b as f64)).collect(),
        Datatype::I8 => data.iter().map(|&b| map(b as i8 as f64)).collect(),
        Datatype::I16 => convert!(i16, 2),
        Datatype::U16 => convert!(u16, 2),
        Datatype::I32 => convert!(i32, 4),
        Datatype::U32 => convert!(u32, 4),
        Datatype::I64 => convert!(i64, 8),
        Datatype::U64 => convert!(u64, 8),
        Datatype::F32 => convert!(f32, 4),
        Datatype::F64 => convert!(f64, 8),
    }
}

/// The header [`write_nifti`] writes for `volume`.
fn header_for(volume: &Volume, path: &Path) -> Result<Header, VolumeError> {
    let dims = volume.dims.to_array();
    if dims.iter().any(|&d| d > i16::MAX as u32) {
        return Err(VolumeError::Write {
            path: path.to_path_buf(),
            source: io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "dimensions {}×{}×{} do not fit NIfTI-1's 16-bit dim fields",
                    dims[0], dims[1], dims[2]
                ),
            ),
        });
    }
    let mut header = Header::new(dims.map(|d| d as i16), Datatype::F32);
    // A brick's origin is its first sample's position.
    let o = if volume.first == UVec3::ZERO {
        volume.origin
    } else {
        volume.position(0, 0, 0)
    };
    let s = volume.spacing;
    header.pixdim[1..4].copy_from_slice(&s.to_array());
    // Scanner-anatomical coordinates with the identity orientation, both ways.
    header.qform_code = 1;
    header.sform_code = 1;
    header.qoffset = o.to_array();
    header.srow = [
        [s.x, 0.0, 0.0, o.x],
        [0.0, s.y, 0.0, o.y],
        [0.0, 0.0, s.z, o.z],
    ];
    Ok(header)
}

/// Writes `volume` as a single-file NIfTI-1 (f32, little endian), gzipped when
/// the name ends in `.gz`.
pub fn write_nifti(volume: &Volume, path: &Path) -> Result<(), VolumeError> {
    let header = header_for(volume, path)?;
    let write_error = |source| VolumeError::Write {
        path: path.to_path_buf(),
        source,
    };
    if volume.values.len() as u64 != sample_count(volume.dims.as_u64vec3().to_array()) {
        return Err(write_error(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "the volume has {} values for {}×{}×{} samples",
                volume.values.len(),
                volume.dims.x,
                volume.dims.y,
                volume.dims.z
            ),
        )));
    }
    let file = BufWriter::new(File::create(path).map_err(write_error)?);
    let gzip = path.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
    let write = |out: &mut dyn Write| -> io::Result<()> {
        out.write_all(&header.to_bytes(Endian::Little))?;
        out.write_all(&[0; DEFAULT_VOX_OFFSET - HEADER_SIZE])?;
        let mut chunk = Vec::with_capacity(4 * 4096);
        for values in volume.values.chunks(4096) {
            chunk.clear();
            chunk.extend(values.iter().flat_map(|v| v.to_le_bytes()));
            out.write_all(&chunk)?;
        }
        Ok(())
    };
    if gzip {
        let mut encoder = GzEncoder::new(file, Compression::default());
        write(&mut encoder).map_err(write_error)?;
        encoder
            .finish()
            .and_then(|mut file| file.flush())
            .map_err(write_error)
    } else {
        let mut file = file;
        write(&mut file).map_err(write_error)?;
        file.flush().map_err(write_error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    /// A NIfTI file's bytes: `header` in `endian` order, zero padding up to
    /// `vox_offset`, then `data` (already in `endian` order); gzipped on request.
    fn nifti_bytes(header: &Header, endian: Endian, data: &[u8], gzip: bool) -> Vec<u8> {
        let mut bytes = header.to_bytes(endian).to_vec();
        bytes.resize(header.vox_offset as usize, 0);
        bytes.extend_from_slice(data);
        if gzip {
            let mut encoder = GzEncoder::new(Vec::new(), Compression::fast());
            encoder.write_all(&bytes).unwrap();
            bytes = encoder.finish().unwrap();
        }
        bytes
    }

    fn encode_i16(values: &[i16], endian: Endian) -> Vec<u8> {
        values
            .iter()
            .flat_map(|v| match endian {
                Endian::Little => v.to_le_bytes(),
                Endian::Big => v.to_be_bytes(),
            })
            .collect()
    }

    fn encode_f32(values: &[f32], endian: Endian) -> Vec<u8> {
        values
            .iter()
            .flat_map(|v| match endian {
                Endian::Little => v.to_le_bytes(),
                Endian::Big => v.to_be_bytes(),
            })
            .collect()
    }

    fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
        let path = dir.path().join(name);
        fs::write(&path, bytes).unwrap();
        path
    }

    const ENDIANS: [Endian; 2] = [Endian::Little, Endian::Big];

    #[test]
    fn header_layout_follows_the_standard() {
        let mut header = Header::new([3, 4, 5], Datatype::I16);
        header.pixdim[1] = 0.5;
        header.vox_offset = 352.0;
        header.srow[2][3] = -7.0;
        let bytes = header.to_bytes(Endian::Little);
        assert_eq!(&bytes[0..4], &348i32.to_le_bytes());
        assert_eq!(&bytes[40..48], &[3, 0, 3, 0, 4, 0, 5, 0]);
        assert_eq!(&bytes[70..74], &[4, 0, 16, 0]); // datatype NIFTI_TYPE_INT16, bitpix
        assert_eq!(&bytes[80..84], &0.5f32.to_le_bytes()); // pixdim[1]
        assert_eq!(&bytes[108..112], &352f32.to_le_bytes());
        assert_eq!(&bytes[324..328], &(-7f32).to_le_bytes()); // srow_z[3]
        assert_eq!(&bytes[344..348], b"n+1\0");
        let big = header.to_bytes(Endian::Big);
        assert_eq!(&big[0..4], &[0, 0, 1, 92]);
        assert_eq!(&big[70..72], &[0, 4]);
    }

    #[test]
    fn reads_u8_i16_and_f32_in_both_byte_orders_plain_and_gzipped() {
        let dir = tempfile::tempdir().unwrap();
        let dims = [3i16, 2, 2];
        let n = 12;
        for endian in ENDIANS {
            for gzip in [false, true] {
                let ext = if gzip { "nii.gz" } else { "nii" };
                let tag = format!("{endian:?}-{gzip}");

                let mut header = Header::new(dims, Datatype::U8);
                header.pixdim[1..4].copy_from_slice(&[0.5, -2.0, 0.0]);
                let data: Vec<u8> = (0..n as u8).map(|v| v * 20).collect();
                let bytes = nifti_bytes(&header, endian, &data, gzip);
                let path = write(&dir, &format!("u8-{tag}.{ext}"), &bytes);
                let volume = Volume::load(&path, None).unwrap();
                assert_eq!(volume.dims, UVec3::new(3, 2, 2), "{tag}");
                assert_eq!(volume.spacing, Vec3::new(0.5, 2.0, 1.0), "{tag}");
                assert_eq!(volume.origin, Vec3::ZERO);
                let expected: Vec<f32> = data.iter().map(|&v| v as f32).collect();
                assert_eq!(volume.values, expected, "{tag}");

                let mut header = Header::new(dims, Datatype::I16);
                header.qform_code = 1;
                header.qoffset = [1.0, 2.0, 3.0];
                let data: Vec<i16> = (0..n).map(|v| v * 1000 - 6000).collect();
                let bytes = nifti_bytes(&header, endian, &encode_i16(&data, endian), gzip);
                let path = write(&dir, &format!("i16-{tag}.{ext}"), &bytes);
                let volume = Volume::load(&path, None).unwrap();
                assert_eq!(volume.origin, Vec3::new(1.0, 2.0, 3.0));
                let expected: Vec<f32> = data.iter().map(|&v| v as f32).collect();
                assert_eq!(volume.values, expected, "{tag}");
                assert_eq!(volume.value(2, 1, 1), 5000.0);

                let mut header = Header::new(dims, Datatype::F32);
                header.vox_offset = 400.0; // room for (ignored) extensions
                header.sform_code = 2;
                header.srow = [[1.0, 0.0, 0.0, -4.0], [0.0; 4], [0.0, 0.0, 0.0, 9.5]];
                header.qform_code = 1;
                header.qoffset = [100.0; 3];
                let data: Vec<f32> = (0..n).map(|v| v as f32 * 0.25 - 1.0).collect();
                let bytes = nifti_bytes(&header, endian, &encode_f32(&data, endian), gzip);
                let path = write(&dir, &format!("f32-{tag}.{ext}"), &bytes);
                let volume = Volume::load(&path, None).unwrap();
                assert_eq!(volume.values, data, "{tag}");
                assert_eq!(volume.origin, Vec3::new(-4.0, 0.0, 9.5), "sform wins");
            }
        }
    }

    #[test]
    fn applies_scaling_and_takes_the_first_of_several_volumes() {
        let dir = tempfile::tempdir().unwrap();
        let mut header = Header::new([2, 2, 2], Datatype::I16);
        header.dim[0] = 4;
        header.dim[4] = 3;
        header.scl_slope = 0.5;
        header.scl_inter = 10.0;
        let data: Vec<i16> = (0..24).collect();
        let bytes = nifti_bytes(&header, Endian::Big, &encode_i16(&data, Endian::Big), false);
        let path = write(&dir, "4d.nii", &bytes);
        let volume = Volume::load(&path, None).unwrap();
        let expected: Vec<f32> = (0..8).map(|v| v as f32 * 0.5 + 10.0).collect();
        assert_eq!(volume.values, expected);
    }

    #[test]
    fn reads_other_data_types() {
        let dir = tempfile::tempdir().unwrap();
        let cases: [(Datatype, Vec<u8>, [f32; 2]); 5] = [
            (Datatype::I8, vec![0xff, 0x05], [-1.0, 5.0]),
            (
                Datatype::U16,
                [65535u16, 7].iter().flat_map(|v| v.to_le_bytes()).collect(),
                [65535.0, 7.0],
            ),
            (
                Datatype::I32,
                [-70000i32, 3]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
                [-70000.0, 3.0],
            ),
            (
                Datatype::F64,
                [0.125f64, -2.5]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
                [0.125, -2.5],
            ),
            (
                Datatype::U64,
                [1u64 << 40, 9]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
                [(1u64 << 40) as f32, 9.0],
            ),
        ];
        for (datatype, two, expected) in cases {
            let header = Header::new([2, 2, 2], datatype);
            let data = two.repeat(4);
            let path = write(
                &dir,
                "t.nii",
                &nifti_bytes(&header, Endian::Little, &data, false),
            );
            let volume = Volume::load(&path, None).unwrap();
            assert_eq!(volume.values, expected.repeat(4), "{datatype:?}");
        }
    }

    #[test]
    fn reads_a_header_and_image_pair() {
        let dir = tempfile::tempdir().unwrap();
        let mut header = Header::new([2, 2, 2], Datatype::U8);
        header.magic = MAGIC_PAIR;
        header.vox_offset = 0.0;
        write(&dir, "pair.hdr", &header.to_bytes(Endian::Little));
        write(&dir, "pair.img", &[1, 2, 3, 4, 5, 6, 7, 8]);
        let volume = Volume::load(dir.path().join("pair.hdr"), None).unwrap();
        assert_eq!(volume.values, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
    }

    fn error_of(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> (VolumeError, String) {
        let path = write(dir, name, bytes);
        let error = Volume::load(&path, None).unwrap_err();
        let message = error.to_string();
        let stem = name.split('.').next().unwrap();
        assert!(message.contains(stem), "{message}");
        (error, message)
    }

    #[test]
    fn truncated_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let header = Header::new([4, 4, 4], Datatype::F32);
        let data = encode_f32(&[1.0; 64], Endian::Little);
        for gzip in [false, true] {
            let whole = nifti_bytes(&header, Endian::Little, &data, false);
            let cut = |len: usize| {
                let bytes = &whole[..len];
                if gzip {
                    let mut encoder = GzEncoder::new(Vec::new(), Compression::fast());
                    encoder.write_all(bytes).unwrap();
                    encoder.finish().unwrap()
                } else {
                    bytes.to_vec()
                }
            };
            let (error, message) = error_of(&dir, "short.nii.gz", &cut(whole.len() - 1));
            assert!(
                matches!(
                    error,
                    VolumeError::Truncated {
                        needed: 608,
                        actual: 607,
                        ..
                    }
                ),
                "{error:?}"
            );
            assert!(message.contains("4×4×4 f32 samples"), "{message}");
            let (error, _) = error_of(&dir, "header.nii", &cut(100));
            assert!(
                matches!(
                    error,
                    VolumeError::Truncated {
                        needed: 348,
                        actual: 100,
                        ..
                    }
                ),
                "{error:?}"
            );
            let (error, _) = error_of(&dir, "empty.nii", &cut(0));
            assert!(
                matches!(error, VolumeError::Truncated { actual: 0, .. }),
                "{error:?}"
            );
        }
        // A gzip stream cut short is an I/O error naming the file.
        let gz = nifti_bytes(&header, Endian::Little, &data, true);
        let (error, _) = error_of(&dir, "cut.nii.gz", &gz[..gz.len() / 2]);
        assert!(
            matches!(
                error,
                VolumeError::Io { .. } | VolumeError::Truncated { .. }
            ),
            "{error:?}"
        );
        // A pair without its image.
        let mut pair = header.clone();
        pair.magic = MAGIC_PAIR;
        let (error, _) = error_of(&dir, "lonely.hdr", &pair.to_bytes(Endian::Big));
        assert!(matches!(error, VolumeError::Io { .. }), "{error:?}");
    }

    #[test]
    fn malformed_headers_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let good = Header::new([4, 4, 4], Datatype::U8);
        let data = [7u8; 64];
        let file = |header: &Header| nifti_bytes(header, Endian::Big, &data, false);

        let mut bytes = file(&good);
        bytes[344..348].copy_from_slice(b"abc\0");
        let (error, message) = error_of(&dir, "magic.nii", &bytes);
        assert!(matches!(error, VolumeError::BadMagic { .. }));
        assert!(message.contains("\"abc\\x00\""), "{message}");
        bytes[344..348].fill(0);
        let (_, message) = error_of(&dir, "analyze.nii", &bytes);
        assert!(message.contains("ANALYZE"), "{message}");
        let mut bytes = file(&good);
        bytes[0..4].copy_from_slice(&1234i32.to_be_bytes());
        let (_, message) = error_of(&dir, "size.nii", &bytes);
        assert!(message.contains("expected 348"), "{message}");
        bytes[0..4].copy_from_slice(&540i32.to_le_bytes());
        let (_, message) = error_of(&dir, "nifti2.nii", &bytes);
        assert!(message.contains("NIfTI-2"), "{message}");

        let mut header = good.clone();
        header.datatype = 128;
        let (error, message) = error_of(&dir, "rgb.nii", &file(&header));
        assert!(matches!(
            error,
            VolumeError::UnsupportedDatatype { code: 128, .. }
        ));
        assert!(message.contains("rgb24"), "{message}");
        header.datatype = 3;
        let (_, message) = error_of(&dir, "weird.nii", &file(&header));
        assert!(message.contains("not a NIfTI data type"), "{message}");

        for dims in [[4, 1, 4], [4, 4, 0], [-3, 4, 4]] {
            let header = Header::new(dims, Datatype::U8);
            let (error, _) = error_of(&dir, "flat.nii", &file(&header));
            assert!(matches!(error, VolumeError::BadDims { .. }), "{error:?}");
        }
        let mut header = good.clone();
        header.dim[0] = 2;
        let (error, _) = error_of(&dir, "rank2.nii", &file(&header));
        assert!(
            matches!(
                error,
                VolumeError::BadDims {
                    dims: [4, 4, 1],
                    ..
                }
            ),
            "{error:?}"
        );
        header.dim[0] = 9;
        let (_, message) = error_of(&dir, "rank9.nii", &file(&header));
        assert!(message.contains("dim[0]"), "{message}");
        let mut header = good.clone();
        header.dim[0] = 4;
        header.dim[4] = 0;
        let (_, message) = error_of(&dir, "novolume.nii", &file(&header));
        assert!(message.contains("dim[4] is 0"), "{message}");

        let header = Header::new([32767, 32767, 32767], Datatype::U8);
        let (error, _) = error_of(&dir, "huge.nii", &file(&header));
        assert!(
            matches!(error, VolumeError::TooManySamples { .. }),
            "{error:?}"
        );

        for offset in [f32::NAN, -4.0, 352.5] {
            let mut header = good.clone();
            header.vox_offset = offset;
            let mut bytes = header.to_bytes(Endian::Little).to_vec();
            bytes.extend_from_slice(&[0; 4]);
            bytes.extend_from_slice(&data);
            let (_, message) = error_of(&dir, "offset.nii", &bytes);
            assert!(message.contains("vox_offset"), "{message}");
        }
        let mut header = good.clone();
        header.vox_offset = 100.0;
        let mut bytes = header.to_bytes(Endian::Little).to_vec();
        bytes.extend_from_slice(&data);
        let (_, message) = error_of(&dir, "inside.nii", &bytes);
        assert!(message.contains("inside the 348-byte header"), "{message}");

        let mut header = good.clone();
        header.sform_code = 1;
        header.srow[0][3] = f32::INFINITY;
        let (_, message) = error_of(&dir, "sform.nii", &file(&header));
        assert!(message.contains("sform offset"), "{message}");
    }

    #[test]
    fn random_bytes_never_panic() {
        let dir = tempfile::tempdir().unwrap();
        let good = nifti_bytes(
            &Header::new([3, 3, 3], Datatype::I16),
            Endian::Little,
            &[1; 54],
            false,
        );
        let mut random = dpp_runtime::random::SplitMix64::new(7);
        for round in 0..200 {
            let mut bytes = good.clone();
            for _ in 0..1 + round % 8 {
                let at = (random.next_u64() % bytes.len() as u64) as usize;
                bytes[at] = random.next_u64() as u8;
            }
            let len = bytes.len() - (random.next_u64() % 8) as usize;
            let path = write(&dir, "fuzz.nii", &bytes[..len]);
            let _ = Volume::load(&path, None);
        }
    }

    #[test]
    fn write_then_read_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let volume = Volume {
            dims: UVec3::new(5, 3, 2),
            spacing: Vec3::new(0.25, 1.5, 2.0),
            origin: Vec3::new(-1.0, 0.5, 8.0),
            first: UVec3::ZERO,
            values: (0..30).map(|v| (v as f32 * 0.37).sin() * 1e3).collect(),
        };
        for name in ["v.nii", "v.nii.gz", "V.NII.GZ"] {
            let path = dir.path().join(name);
            volume.write_nifti(&path).unwrap();
            assert_eq!(Volume::load(&path, None).unwrap(), volume, "{name}");
        }
        let bytes = fs::read(dir.path().join("v.nii")).unwrap();
        assert_eq!(bytes.len(), 352 + 30 * 4);
        assert_eq!(
            fs::read(dir.path().join("v.nii.gz")).unwrap()[..2],
            [0x1f, 0x8b]
        );

        let mut bad = volume.clone();
        bad.values.pop();
        assert!(matches!(
            bad.write_nifti(dir.path().join("b.nii")),
            Err(VolumeError::Write { .. })
        ));
        let missing = dir.path().join("no/such/dir/v.nii");
        let error = volume.write_nifti(&missing).unwrap_err();
        assert!(error.to_string().contains("no/such/dir"), "{error}");
    }

    #[test]
    fn a_box_read_is_the_same_sub_box_of_the_whole_read() {
        use crate::volume::generate::Dataset;
        use crate::volume::kd_bricks;
        let dir = tempfile::tempdir().unwrap();
        let dims = UVec3::new(9, 7, 6);
        let mut whole = Dataset::RichtmyerMeshkov.generate(dims).unwrap();
        whole.origin = Vec3::new(-3.0, 0.25, 7.0);
        for name in ["w.nii", "w.nii.gz"] {
            let path = dir.path().join(name);
            whole.write_nifti(&path).unwrap();
            let read = Volume::load(&path, None).unwrap();
            assert_eq!(Volume::read_dims(&path, None).unwrap(), dims);
            for parts in 1..=5 {
                for brick in kd_bricks(dims - UVec3::ONE, parts) {
                    let part = Volume::load_brick(&path, None, &brick).unwrap();
                    let expected = read.sub_box(brick.samples[0], brick.samples[1]);
                    assert_eq!(part, expected, "{name} {brick:?}");
                }
            }
            let error = read_nifti_box(&path, [UVec3::ZERO, dims + UVec3::Z]).unwrap_err();
            assert!(error.to_string().contains("not inside"), "{error}");
        }
        // Truncated data is an error, plain or gzipped.
        let bytes = fs::read(dir.path().join("w.nii")).unwrap();
        let short = write(&dir, "short.nii", &bytes[..bytes.len() - 4]);
        let box_ = [UVec3::new(1, 1, 1), dims];
        assert!(matches!(
            read_nifti_box(&short, box_),
            Err(VolumeError::Truncated { .. })
        ));
        let mut gz = GzEncoder::new(Vec::new(), Compression::fast());
        gz.write_all(&bytes[..bytes.len() - 4]).unwrap();
        let short = write(&dir, "short.nii.gz", &gz.finish().unwrap());
        assert!(matches!(
            read_nifti_box(&short, box_),
            Err(VolumeError::Truncated { .. })
        ));
    }
}
