//! VTK image data as a [`Volume`]: `.vti`, legacy `.vtk` structured points,
//! and `.pvti` whose piece files are assembled into one volume.
//!
//! Sample `(i, j, k)` of the whole extent `[x0..=x1, y0..=y1, z0..=z1]` is at
//! `Origin + Spacing * (x0 + i, y0 + j, z0 + k)` (VTK's definition), so the
//! volume's origin is `Origin + Spacing * (x0, y0, z0)`. `Direction` (a
//! rotation, VTK 9) is not applied, as NIfTI's qform/sform rotations are not.

use super::{inline_pieces, parse, Association, FieldChoice, VtkError, VtkKind};
use crate::volume::{sample_count, Volume, MAX_SAMPLES};
use glam::{UVec3, Vec3};
use std::ops::RangeInclusive;
use std::path::Path;
use vtkio::model::{DataSet, Extent, ImageDataPiece};

/// Reads the volume of `path` (`.vti`, `.pvti`, or a legacy `.vtk` of
/// structured points): the point field `field` chooses, on the whole extent.
/// A piece's samples go to its extent's place; samples no piece covers, a
/// missing piece file or a field on cells are errors.
pub fn read_volume(path: &Path, field: &FieldChoice) -> Result<Volume, VtkError> {
    let DataSet::ImageData {
        extent,
        origin,
        spacing,
        pieces,
        ..
    } = parse(path)?
    else {
        return Err(VtkError::new(
            path,
            "not image data (a volume): dpp reads .vti, .pvti and legacy STRUCTURED_POINTS as volumes",
        ));
    };
    let whole = ranges(path, extent)?;
    let dims = UVec3::from(whole.clone().map(|r| (r.end() - r.start() + 1) as u32));
    let count = sample_count(dims.as_u64vec3().to_array());
    if count > MAX_SAMPLES {
        return Err(VtkError::new(
            path,
            format!(
                "{}×{}×{} = {count} samples is too many (at most {MAX_SAMPLES})",
                dims.x, dims.y, dims.z
            ),
        ));
    }
    let spacing = Vec3::from(spacing);
    if !spacing.is_finite() || spacing.cmple(Vec3::ZERO).any() {
        return Err(VtkError::new(
            path,
            format!("the spacing {spacing} must be positive and finite"),
        ));
    }
    let start = Vec3::new(
        *whole[0].start() as f32,
        *whole[1].start() as f32,
        *whole[2].start() as f32,
    );
    let origin = Vec3::from(origin) + spacing * start;
    if !origin.is_finite() {
        return Err(VtkError::new(path, "the origin is not finite"));
    }
    let mut values = vec![0.0f32; count as usize];
    let mut covered = vec![false; count as usize];
    let mut choice = field.clone();
    let parallel = VtkKind::of(path) == Some(VtkKind::Image { parallel: true });
    let pieces = if parallel {
        let mut loaded = Vec::new();
        for file in super::piece_files(path)? {
            let DataSet::ImageData { pieces, .. } = parse(&file)? else {
                return Err(VtkError::new(
                    &file,
                    "a piece of a .pvti that is not image data",
                ));
            };
            loaded.extend(
                inline_pieces(&file, pieces)?
                    .into_iter()
                    .map(|p| (file.clone(), p)),
            );
        }
        loaded
    } else {
        (inline_pieces(path, pieces)?.into_iter())
            .map(|p| (path.to_path_buf(), p))
            .collect()
    };
    for (file, piece) in pieces {
        choice = place_piece(&file, piece, &whole, &choice, &mut values, &mut covered)?;
    }
    if let Some(gap) = covered.iter().position(|c| !c) {
        return Err(VtkError::new(
            path,
            format!("sample {gap} of the whole extent is in no piece"),
        ));
    }
    Ok(Volume {
        dims,
        spacing,
        origin,
        first: UVec3::ZERO,
        values,
    })
}

/// Copies one piece's samples into the whole volume; returns the choice
/// made concrete, for the next pieces.
fn place_piece(
    file: &Path,
    piece: ImageDataPiece,
    whole: &[RangeInclusive<i32>; 3],
    choice: &FieldChoice,
    values: &mut [f32],
    covered: &mut [bool],
) -> Result<FieldChoice, VtkError> {
    let own = ranges(file, piece.extent)?;
    if (0..3).any(|a| own[a].start() < whole[a].start() || own[a].end() > whole[a].end()) {
        return Err(VtkError::new(
            file,
            format!("a piece's extent {own:?} lies outside the whole extent {whole:?}"),
        ));
    }
    let len = |r: &RangeInclusive<i32>| (r.end() - r.start() + 1) as usize;
    let points = own.iter().map(len).product::<usize>();
    let cells = own
        .iter()
        .map(|r| len(r).saturating_sub(1).max(1))
        .product();
    let Some((field, concrete)) = choice.pick(file, &piece.data, points, cells)? else {
        return Err(VtkError::new(
            file,
            format!("the volume has no point data arrays{}", super::XML_DROPS),
        ));
    };
    if field.association == Association::Cell {
        return Err(VtkError::new(
            file,
            format!(
                "`{}` is cell data; a volume's field must be point data (one value per sample)",
                concrete.name.as_deref().unwrap_or_default()
            ),
        ));
    }
    let [nx, ny] = [len(&whole[0]), len(&whole[1])];
    let mut from = field.values.iter();
    for k in own[2].clone() {
        for j in own[1].clone() {
            for i in own[0].clone() {
                let at = (i - whole[0].start()) as usize
                    + nx * ((j - whole[1].start()) as usize + ny * (k - whole[2].start()) as usize);
                // `pick` checked that there is one value per point.
                values[at] = *from.next().unwrap_or(&f32::NAN);
                covered[at] = true;
            }
        }
    }
    Ok(concrete)
}

/// An extent as inclusive index ranges (a legacy file's dimensions start
/// at 0), each non-empty.
fn ranges(path: &Path, extent: Extent) -> Result<[RangeInclusive<i32>; 3], VtkError> {
    let ranges = match extent {
        Extent::Dims(dims) => dims.map(|n| 0..=(n as i64 - 1).clamp(-1, i32::MAX as i64) as i32),
        Extent::Ranges(ranges) => ranges,
    };
    if ranges.iter().any(|r| r.is_empty()) {
        return Err(VtkError::new(
            path,
            format!("the extent {ranges:?} is empty"),
        ));
    }
    Ok(ranges)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vtk::{fixture, read_mutated_fixtures};

    /// The fixture volume as `scripts/make-vtk-fixtures.py` defines it.
    fn expected() -> Volume {
        let dims = UVec3::new(9, 8, 7);
        let spacing = Vec3::new(0.5, 0.25, 1.0);
        let origin = Vec3::new(-2.0, -1.0, -3.0);
        let mut values = Vec::new();
        for k in 0..dims.z {
            for j in 0..dims.y {
                for i in 0..dims.x {
                    let p = origin + spacing * UVec3::new(i, j, k).as_vec3();
                    values.push(p.length());
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

    #[test]
    fn every_encoding_reads_the_same_volume() {
        let expected = expected();
        for name in [
            "ball_ascii.vti",
            "ball_binary.vti",
            "ball_appended.vti",
            "ball_zlib.vti",
            "ball_lz4.vti",
            "ball_be.vti",
            "ball.pvti",
            "ball_legacy.vtk",
            "ball_legacy_binary.vtk",
        ] {
            let volume = read_volume(&fixture(name), &FieldChoice::default())
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(volume.dims, expected.dims, "{name}");
            assert_eq!(volume.spacing, expected.spacing, "{name}");
            assert_eq!(volume.origin, expected.origin, "{name}");
            for (a, b) in volume.values.iter().zip(&expected.values) {
                assert!((a - b).abs() < 1e-5, "{name}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn vectors_and_integer_arrays_by_name() {
        let path = fixture("ball_appended.vti");
        let pick = |text: &str| read_volume(&path, &text.parse().unwrap());
        let expected = expected();
        let magnitude = pick("position:mag").unwrap();
        let x = pick("position:0").unwrap();
        let whole = pick("position").unwrap();
        let ids = pick("id").unwrap();
        for index in 0..expected.values.len() {
            let ijk = expected.ijk(index);
            let p = expected.position(ijk.x, ijk.y, ijk.z);
            assert!((magnitude.values[index] - p.length()).abs() < 1e-5);
            assert!((whole.values[index] - p.length()).abs() < 1e-5);
            assert_eq!(x.values[index], p.x);
            assert_eq!(ids.values[index], index as f32);
        }
        let error = pick("position:3").unwrap_err().to_string();
        assert!(error.contains("component 3"), "{error}");
        let error = pick("nope").unwrap_err().to_string();
        assert!(
            error.contains("ball_appended.vti") && error.contains("distance (points)"),
            "{error}"
        );
        let error = pick("cellid").unwrap_err().to_string();
        assert!(error.contains("cell data"), "{error}");
    }

    #[test]
    fn a_box_of_a_vtk_volume_is_that_box_of_the_whole() {
        let path = fixture("ball.pvti");
        let whole = Volume::load(&path, None).unwrap();
        assert_eq!(Volume::read_dims(&path, None).unwrap(), whole.dims);
        let (lo, hi) = (UVec3::new(1, 2, 3), UVec3::new(5, 8, 7));
        let part = Volume::load_box(&path, None, [lo, hi]).unwrap();
        assert_eq!(part, whole.sub_box(lo, hi));
        assert!(Volume::load_box(&path, None, [lo, UVec3::new(5, 8, 8)]).is_err());
    }

    #[test]
    fn raw_appended_data_is_a_clear_error() {
        let error = read_volume(&fixture("ball_raw.vti"), &FieldChoice::default())
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("ball_raw.vti") && error.contains("raw"),
            "{error}"
        );
    }

    #[test]
    fn a_missing_piece_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let pvti = dir.path().join("ball.pvti");
        std::fs::copy(fixture("ball.pvti"), &pvti).unwrap();
        for piece in ["ball/ball_0.vti", "ball/ball_1.vti"] {
            std::fs::create_dir_all(dir.path().join("ball")).unwrap();
            std::fs::copy(fixture(piece), dir.path().join(piece)).unwrap();
        }
        let error = read_volume(&pvti, &FieldChoice::default())
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("ball_2.vti") && error.contains("missing"),
            "{error}"
        );
    }

    #[test]
    fn mutated_files_never_panic() {
        let names = [
            "ball_ascii.vti",
            "ball_appended.vti",
            "ball_zlib.vti",
            "ball_lz4.vti",
            "ball_legacy_binary.vtk",
        ];
        read_mutated_fixtures(&names, 11, 60, |path| {
            let _ = read_volume(path, &FieldChoice::default());
        });
    }
}
