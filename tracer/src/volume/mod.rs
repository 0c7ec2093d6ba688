//! Scalar volumes (a regular grid of samples) for isosurfaces: read from NIfTI
//! files or raw bricks, or generated (the paper's data sets, procedurally).
//!
//! - [`Volume::load`] reads a NIfTI-1 file (`.nii`, `.nii.gz`, or a `.hdr`/`.img`
//!   pair; [`nifti`]), VTK image data (`.vti`, `.pvti`, legacy structured
//!   points; [`crate::vtk::volume`]) or, given a [`RawSpec`], a raw brick ([`raw`]).
//! - [`generate`] makes the paper's data sets procedurally (a Richtmyer–Meshkov
//!   mixing layer, a lead-telluride crystal) and simple test fields.
//! - [`Volume::validate`] checks what marching cubes relies on (call it on loaded
//!   data: a loader keeps NaNs, which some files use to mark "no data").
//! - [`Volume::write_nifti`] writes a volume as NIfTI-1 (f32, little endian).

pub mod brick;
pub mod generate;
pub mod nifti;
pub mod raw;

pub use brick::{kd_bricks, Brick};
pub use raw::{RawSpec, RawType};

use crate::mesh::Bounds;
use glam::{UVec3, Vec3};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// At most this many samples in a volume (2³¹: 8 GiB of `f32`).
pub const MAX_SAMPLES: u64 = 1 << 31;

/// Samples on a regular grid, x fastest: sample `(i, j, k)` is at
/// `origin + spacing * (first + (i, j, k))` and stored at
/// `i + dims.x * (j + dims.y * k)`.
///
/// `first` is the global index of sample `(0, 0, 0)` when the volume is a
/// brick of a larger one ([`brick`]; zero for a whole volume): positions are
/// computed from the global index, so a brick's are bit-identical to the
/// whole volume's (folding `first` into `origin` would round differently).
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    pub dims: UVec3,
    pub spacing: Vec3,
    pub origin: Vec3,
    /// The global index of sample `(0, 0, 0)`; zero for a whole volume.
    pub first: UVec3,
    pub values: Vec<f32>,
}

/// Byte order of binary data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Endian {
    #[default]
    Little,
    Big,
}

/// Everything that can go wrong reading, generating or checking a volume. Errors
/// about a file name it; none of the readers panics on malformed input.
#[derive(Debug, Error)]
pub enum VolumeError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: not a NIfTI-1 file: {what}", path.display())]
    BadMagic { path: PathBuf, what: String },
    #[error("{}: malformed NIfTI-1 header: {what}", path.display())]
    BadHeader { path: PathBuf, what: String },
    #[error(
        "{}: unsupported NIfTI data type {code} ({name}); supported: u8, i8, i16, u16, i32, u32, i64, u64, f32, f64",
        path.display()
    )]
    UnsupportedDatatype {
        path: PathBuf,
        code: i16,
        name: &'static str,
    },
    #[error(
        "{}: a volume needs at least 2 samples along x, y and z, but its dimensions are {}×{}×{}",
        path.display(), dims[0], dims[1], dims[2]
    )]
    BadDims { path: PathBuf, dims: [i64; 3] },
    #[error(
        "{}: the file is too short: {what} needs {needed} bytes, but only {actual} are there",
        path.display()
    )]
    Truncated {
        path: PathBuf,
        what: String,
        needed: u64,
        actual: u64,
    },
    #[error(
        "{}: {}×{}×{} = {count} samples is too many (at most {MAX_SAMPLES})",
        path.display(), dims[0], dims[1], dims[2]
    )]
    TooManySamples {
        path: PathBuf,
        dims: [u64; 3],
        count: u64,
    },
    #[error("{}: {what}", path.display())]
    RawSize { path: PathBuf, what: String },
    #[error(transparent)]
    Vtk(#[from] crate::vtk::VtkError),
    #[error(
        "{}: unknown volume file type (expected .nii, .nii.gz, .hdr, .vti, .pvti or a legacy .vtk of structured points; give the dimensions and sample type to read a raw brick)",
        path.display()
    )]
    UnknownFileType { path: PathBuf },
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the volume needs at least 2 samples along x, y and z, but its dimensions are {}×{}×{}", dims.x, dims.y, dims.z)]
    TooSmall { dims: UVec3 },
    #[error("a {}×{}×{} volume needs {expected} samples, but it has {actual}", dims.x, dims.y, dims.z)]
    LengthMismatch {
        dims: UVec3,
        expected: u64,
        actual: usize,
    },
    #[error("sample {index} (i, j, k = {}, {}, {}) is not finite: {value}", ijk.x, ijk.y, ijk.z)]
    NonFinite {
        index: usize,
        ijk: UVec3,
        value: f32,
    },
    #[error("invalid raw volume description '{spec}': {what}")]
    BadRawSpec { spec: String, what: String },
    #[error("unknown volume '{name}'{}; known volumes: {}", suggestion_text(suggestion), known.join(", "))]
    UnknownVolume {
        name: String,
        suggestion: Option<&'static str>,
        known: &'static [&'static str],
    },
    #[error(
        "cannot generate a {}×{}×{} volume: {what}",
        dims.x, dims.y, dims.z
    )]
    BadGenerateDims { dims: UVec3, what: &'static str },
}

fn suggestion_text(suggestion: &Option<&'static str>) -> String {
    match suggestion {
        Some(name) => format!(" (did you mean '{name}'?)"),
        None => String::new(),
    }
}

/// Fails unless the name ends in `.nii`, `.nii.gz`, `.hdr` or `.hdr.gz`.
fn check_nifti_name(path: &Path) -> Result<(), VolumeError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if [".nii", ".nii.gz", ".hdr", ".hdr.gz"]
        .iter()
        .any(|ext| name.ends_with(ext))
    {
        Ok(())
    } else {
        Err(VolumeError::UnknownFileType {
            path: path.to_path_buf(),
        })
    }
}

/// Number of samples of `dims`, as u64 (never overflows).
pub(crate) fn sample_count(dims: [u64; 3]) -> u64 {
    dims[0].saturating_mul(dims[1]).saturating_mul(dims[2])
}

impl Volume {
    /// Reads a volume: a raw brick when `raw` is given, else by extension a NIfTI-1
    /// file (`.nii`, `.nii.gz`, or a `.hdr` with its `.img`). Dimensions are checked
    /// (at least 2 along each axis, at most [`MAX_SAMPLES`] samples); values are
    /// not: call [`Volume::validate`] before meshing.
    pub fn load(path: impl AsRef<Path>, raw: Option<RawSpec>) -> Result<Volume, VolumeError> {
        let path = path.as_ref();
        if let Some(spec) = raw {
            return raw::read_raw(path, &spec);
        }
        if crate::vtk::is_volume_file(path) {
            let default = crate::vtk::FieldChoice::default();
            return Ok(crate::vtk::volume::read_volume(path, &default)?);
        }
        check_nifti_name(path)?;
        nifti::read_nifti(path)
    }

    /// The sample dimensions of the volume [`Volume::load`] would read, from the
    /// raw spec (after checking the file's size) or the NIfTI header alone:
    /// what a caller needs to split the volume into bricks before reading one.
    pub fn read_dims(path: impl AsRef<Path>, raw: Option<RawSpec>) -> Result<UVec3, VolumeError> {
        let path = path.as_ref();
        match raw {
            Some(spec) => raw::raw_dims(path, &spec),
            // VTK has no header to read alone: the whole file is read.
            None if crate::vtk::is_volume_file(path) => Ok(Volume::load(path, None)?.dims),
            None => {
                check_nifti_name(path)?;
                nifti::nifti_dims(path)
            }
        }
    }

    /// Reads only `brick`'s samples (its `samples` box, ghost layers
    /// included) of the volume [`Volume::load`] would read: the same values
    /// as that box of the whole volume, with `first` its lowest sample. Raw
    /// and uncompressed NIfTI files are read by seeking, row by row; a gzipped
    /// NIfTI file is decompressed as a stream (see [`nifti::read_nifti_box`]:
    /// every reader decompresses up to its brick, but keeps only its brick).
    pub fn load_brick(
        path: impl AsRef<Path>,
        raw: Option<RawSpec>,
        brick: &Brick,
    ) -> Result<Volume, VolumeError> {
        Volume::load_box(path, raw, brick.samples)
    }

    /// Reads only the samples `[samples[0], samples[1])` (global indices,
    /// inside the volume) of the volume [`Volume::load`] would read.
    pub fn load_box(
        path: impl AsRef<Path>,
        raw: Option<RawSpec>,
        samples: [UVec3; 2],
    ) -> Result<Volume, VolumeError> {
        let path = path.as_ref();
        match raw {
            Some(spec) => raw::read_raw_box(path, &spec, samples),
            None if crate::vtk::is_volume_file(path) => {
                let whole = Volume::load(path, None)?;
                raw::check_box(path, whole.dims, samples)?;
                Ok(whole.sub_box(samples[0], samples[1]))
            }
            None => {
                check_nifti_name(path)?;
                nifti::read_nifti_box(path, samples)
            }
        }
    }

    /// The samples `[lo, hi)` (indices in this volume, inside it), with
    /// `first = lo`.
    pub fn sub_box(&self, lo: UVec3, hi: UVec3) -> Volume {
        let mut values = Vec::new();
        for k in lo.z..hi.z {
            for j in lo.y..hi.y {
                for i in lo.x..hi.x {
                    values.push(self.value(i, j, k));
                }
            }
        }
        Volume {
            dims: hi - lo,
            spacing: self.spacing,
            origin: self.origin,
            first: lo,
            values,
        }
    }

    /// Writes the volume as a NIfTI-1 file (f32 samples, little endian), gzipped
    /// when the name ends in `.gz`. Spacing and origin are kept (pixdim and an
    /// identity-oriented qform/sform).
    pub fn write_nifti(&self, path: impl AsRef<Path>) -> Result<(), VolumeError> {
        nifti::write_nifti(self, path.as_ref())
    }

    /// Checks what marching cubes relies on: at least 2 samples along each axis,
    /// one value per sample, every value finite (the error names the first bad one).
    pub fn validate(&self) -> Result<(), VolumeError> {
        if self.dims.cmplt(UVec3::splat(2)).any() {
            return Err(VolumeError::TooSmall { dims: self.dims });
        }
        let expected = sample_count(self.dims.as_u64vec3().to_array());
        if expected != self.values.len() as u64 {
            return Err(VolumeError::LengthMismatch {
                dims: self.dims,
                expected,
                actual: self.values.len(),
            });
        }
        if let Some(index) = self.values.iter().position(|v| !v.is_finite()) {
            return Err(VolumeError::NonFinite {
                index,
                ijk: self.ijk(index),
                value: self.values[index],
            });
        }
        Ok(())
    }

    /// `f(position, sample)` at every sample of a `dims` grid spaced `spacing`
    /// apart from `origin`, in storage order (x fastest). Not validated.
    pub fn from_fn(
        dims: UVec3,
        origin: Vec3,
        spacing: Vec3,
        f: impl Fn(Vec3, UVec3) -> f32,
    ) -> Volume {
        let mut values = Vec::with_capacity(sample_count(dims.as_u64vec3().to_array()) as usize);
        for k in 0..dims.z {
            for j in 0..dims.y {
                for i in 0..dims.x {
                    let sample = UVec3::new(i, j, k);
                    values.push(f(origin + spacing * sample.as_vec3(), sample));
                }
            }
        }
        Volume {
            dims,
            spacing,
            origin,
            first: UVec3::ZERO,
            values,
        }
    }

    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        i as usize + self.dims.x as usize * (j as usize + self.dims.y as usize * k as usize)
    }

    /// The grid coordinates of the sample stored at `index`.
    pub fn ijk(&self, index: usize) -> UVec3 {
        let (nx, ny) = (self.dims.x.max(1) as usize, self.dims.y.max(1) as usize);
        UVec3::new(
            (index % nx) as u32,
            (index / nx % ny) as u32,
            (index / nx / ny) as u32,
        )
    }

    pub fn value(&self, i: u32, j: u32, k: u32) -> f32 {
        self.values[self.index(i, j, k)]
    }

    /// The world position of sample `(i, j, k)`: `origin + spacing * (first +
    /// (i, j, k))`, the global index converted to f32 once.
    pub fn position(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.origin + self.spacing * (self.first + UVec3::new(i, j, k)).as_vec3()
    }

    /// Cells are the cubes between 2×2×2 neighbouring samples.
    pub fn cell_dims(&self) -> UVec3 {
        self.dims.saturating_sub(UVec3::ONE)
    }

    pub fn cell_count(&self) -> u64 {
        let c = self.cell_dims();
        c.x as u64 * c.y as u64 * c.z as u64
    }

    /// The smallest and largest finite values, or `None` when there are none.
    pub fn value_range(&self) -> Option<(f32, f32)> {
        self.values
            .iter()
            .filter(|v| v.is_finite())
            .fold(None, |range, &v| match range {
                None => Some((v, v)),
                Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
            })
    }

    /// The world-space box spanned by the samples the volume holds, from the
    /// first sample's position to the last's (min ≤ max even where a spacing is
    /// negative).
    pub fn bounds(&self) -> Bounds {
        let first = self.position(0, 0, 0);
        let last = self.dims.saturating_sub(UVec3::ONE);
        let last = self.position(last.x, last.y, last.z);
        Bounds {
            min: first.min(last),
            max: first.max(last),
        }
    }

    /// The field's gradient at sample `(i, j, k)` in world units (per unit of
    /// distance, so spacing is taken into account): central differences inside,
    /// one-sided differences on the border, 0 along an axis with a single sample.
    /// Marching cubes interpolates it for vertex normals (which point along
    /// `-gradient` to face towards lower values).
    pub fn gradient(&self, i: u32, j: u32, k: u32) -> Vec3 {
        let axis = |n: u32, at: u32, sample: &dyn Fn(u32) -> f32, h: f32| -> f32 {
            if n < 2 {
                return 0.0;
            }
            let (lo, hi) = (at.saturating_sub(1), (at + 1).min(n - 1));
            (sample(hi) - sample(lo)) / ((hi - lo) as f32 * h)
        };
        Vec3::new(
            axis(self.dims.x, i, &|x| self.value(x, j, k), self.spacing.x),
            axis(self.dims.y, j, &|y| self.value(i, y, k), self.spacing.y),
            axis(self.dims.z, k, &|z| self.value(i, j, z), self.spacing.z),
        )
    }

    /// The number of cells whose 8 corners do not all lie on the same side of
    /// `level` (a corner is "inside" when its value is `>= level`): the cells
    /// marching cubes puts triangles in (about two each on smooth surfaces).
    pub fn crossing_cell_count(&self, level: f32) -> u64 {
        use rayon::prelude::*;
        let c = self.cell_dims();
        if c.cmpeq(UVec3::ZERO).any() || self.values.len() as u64 != self.dims_count() {
            return 0;
        }
        let (nx, plane) = (
            self.dims.x as usize,
            self.dims.x as usize * self.dims.y as usize,
        );
        (0..c.z as usize)
            .into_par_iter()
            .map(|k| {
                // Per row pair, whether each sample is inside; then per cell.
                let mut count = 0u64;
                let inside = |index: usize| self.values[index] >= level;
                for j in 0..c.y as usize {
                    let base = k * plane + j * nx;
                    let corners = [base, base + nx, base + plane, base + plane + nx];
                    let column = |i: usize| -> u8 {
                        corners
                            .iter()
                            .enumerate()
                            .map(|(b, &row)| (inside(row + i) as u8) << b)
                            .sum()
                    };
                    let mut left = column(0);
                    for i in 1..nx {
                        let right = column(i);
                        let cell = left | right << 4;
                        count += u64::from(cell != 0 && cell != 0xff);
                        left = right;
                    }
                }
                count
            })
            .sum()
    }

    fn dims_count(&self) -> u64 {
        sample_count(self.dims.as_u64vec3().to_array())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(dims: UVec3, f: impl Fn(Vec3) -> f32) -> Volume {
        let mut v = Volume {
            dims,
            spacing: Vec3::new(0.5, 2.0, 1.0),
            origin: Vec3::new(1.0, -1.0, 3.0),
            first: UVec3::ZERO,
            values: vec![0.0; (dims.x * dims.y * dims.z) as usize],
        };
        for k in 0..dims.z {
            for j in 0..dims.y {
                for i in 0..dims.x {
                    let index = v.index(i, j, k);
                    v.values[index] = f(v.position(i, j, k));
                }
            }
        }
        v
    }

    #[test]
    fn gradient_of_a_linear_field_is_exact_everywhere() {
        let v = ramp(UVec3::new(4, 3, 5), |p| 2.0 * p.x - 3.0 * p.y + 0.5 * p.z);
        for (i, j, k) in [(0, 0, 0), (3, 2, 4), (1, 1, 2), (3, 0, 1)] {
            let g = v.gradient(i, j, k);
            assert!((g - Vec3::new(2.0, -3.0, 0.5)).length() < 1e-5, "{g:?}");
        }
    }

    #[test]
    fn gradient_uses_central_differences_inside() {
        let v = ramp(UVec3::new(5, 2, 2), |p| p.x * p.x);
        // x = 1 + 0.5 i; at i = 2 (x = 2) the central difference of x² is exact: 4.
        assert!((v.gradient(2, 0, 0).x - 4.0).abs() < 1e-5);
        // One-sided at the border: (x(1)² - x(0)²) / 0.5 = (2.25 - 1) / 0.5.
        assert!((v.gradient(0, 1, 1).x - 2.5).abs() < 1e-5);
    }

    #[test]
    fn bounds_range_and_index_round_trip() {
        let v = ramp(UVec3::new(4, 3, 2), |p| p.x + p.y);
        let b = v.bounds();
        assert_eq!(b.min, Vec3::new(1.0, -1.0, 3.0));
        assert_eq!(b.max, Vec3::new(2.5, 3.0, 4.0));
        assert_eq!(v.value_range(), Some((0.0, 5.5)));
        for index in 0..v.values.len() {
            let ijk = v.ijk(index);
            assert_eq!(v.index(ijk.x, ijk.y, ijk.z), index);
        }
    }

    #[test]
    fn validate_names_the_first_bad_sample() {
        let mut v = ramp(UVec3::new(3, 3, 3), |p| p.x);
        assert!(v.validate().is_ok());
        let (first, second) = (v.index(1, 2, 0), v.index(2, 2, 2));
        v.values[first] = f32::NAN;
        v.values[second] = f32::INFINITY;
        let error = v.validate().unwrap_err();
        assert!(
            matches!(error, VolumeError::NonFinite { index: 7, ijk, .. } if ijk == UVec3::new(1, 2, 0)),
            "{error:?}"
        );
        assert!(error.to_string().contains("sample 7 (i, j, k = 1, 2, 0)"));
        v.values.pop();
        assert!(matches!(
            v.validate(),
            Err(VolumeError::LengthMismatch { .. })
        ));
        let flat = ramp(UVec3::new(3, 1, 3), |p| p.x);
        assert!(matches!(flat.validate(), Err(VolumeError::TooSmall { .. })));
    }

    #[test]
    fn crossing_cells_of_a_plane() {
        // The plane x = 1.6 (between samples 1 and 2 of x = 1 + 0.5 i) crosses one
        // layer of cells: 1 × 4 × 3.
        let v = ramp(UVec3::new(6, 5, 4), |p| p.x - 1.6);
        assert_eq!(v.crossing_cell_count(0.0), 12);
        assert_eq!(v.crossing_cell_count(100.0), 0);
        assert_eq!(v.crossing_cell_count(-100.0), 0);
    }

    #[test]
    fn load_rejects_unknown_extensions() {
        let error = Volume::load("brick.dat", None).unwrap_err();
        assert!(matches!(error, VolumeError::UnknownFileType { .. }));
        assert!(error.to_string().contains("brick.dat"));
    }
}
