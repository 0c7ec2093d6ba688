//! Volumes as scenes: a NIfTI file, a raw brick or a generated data set
//! becomes triangles through the marching-cubes pipeline
//! (`pipelines/isosurface.dpp`, built into the command so it runs anywhere;
//! `--iso-pipeline` runs an edited copy instead).

use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::OutputValue;
use dpp_runtime::{compile_file, compile_text, CompileOptions, FunctorLibrary};
use dpp_tracer::functors::isosurface::{triangles_to_mesh, volume_uniforms, VolumeResources};
use dpp_tracer::volume::raw::RawSpec;
use dpp_tracer::volume::Volume;
use dpp_tracer::vtk::FieldChoice;
use dpp_tracer::TriangleMesh;
use std::path::{Path, PathBuf};
use std::sync::Arc;

const ISOSURFACE_PIPELINE: &str = include_str!("../pipelines/isosurface.dpp");

/// Whether a scene path names a volume rather than a mesh (a legacy `.vtk`
/// by its `DATASET` line).
pub fn is_volume_path(path: &Path) -> bool {
    let name = path.to_string_lossy().to_ascii_lowercase();
    name.ends_with(".nii") || name.ends_with(".nii.gz") || dpp_tracer::vtk::is_volume_file(path)
}

/// A VTK file's array as `--field` names it (`NAME`, `NAME:mag`, `NAME:0`);
/// none: the file's active scalars, else its first array.
pub fn field_choice(field: Option<&str>) -> Result<FieldChoice, String> {
    field.map_or(Ok(FieldChoice::default()), |text| {
        text.parse().map_err(|e| format!("error: {e}"))
    })
}

/// A volume from a NIfTI or VTK file (`field`: which VTK array), or a raw
/// brick described by `raw` (`XxYxZ:TYPE…`).
pub fn load_volume(path: &Path, raw: Option<&str>, field: Option<&str>) -> Result<Volume, String> {
    let raw = raw
        .map(|spec| spec.parse::<RawSpec>())
        .transpose()
        .map_err(|e| format!("error: {e}"))?;
    let volume = match field {
        Some(_) if raw.is_none() && dpp_tracer::vtk::is_volume_file(path) => {
            dpp_tracer::vtk::volume::read_volume(path, &field_choice(field)?)
                .map_err(|e| format!("error: {e}"))?
        }
        Some(field) => {
            return Err(format!(
                "error: --field {field} chooses an array of a VTK file; {} has one field",
                path.display()
            ))
        }
        None => Volume::load(path, raw).map_err(|e| format!("error: {e}"))?,
    };
    volume
        .validate()
        .map_err(|e| format!("error: {}: {e}", path.display()))?;
    Ok(volume)
}

/// A volume as a run reads it directly: what a pipeline that reads
/// `volume.*` (marching cubes, `pipelines/isosurface.dpp`) runs on.
pub struct VolumeRun {
    pub uniforms: dpp_runtime::Uniforms,
    pub resources: VolumeResources,
    /// One line for `--profile` and messages: the file and its samples.
    pub description: String,
}

/// Loads the volume at `path` (a raw brick with `raw`, a VTK file's array
/// `field`) for a run on the volume itself.
pub fn volume_run(
    path: &Path,
    raw: Option<&str>,
    field: Option<&str>,
) -> Result<VolumeRun, String> {
    let volume = load_volume(path, raw, field)?;
    let description = format!(
        "the volume {} ({}x{}x{} samples)",
        path.display(),
        volume.dims.x,
        volume.dims.y,
        volume.dims.z
    );
    Ok(VolumeRun {
        uniforms: volume_uniforms(&volume),
        resources: VolumeResources {
            volume: Arc::new(volume),
        },
        description,
    })
}

/// How to extract an isosurface.
pub struct IsoRequest {
    pub level: f32,
    /// An edited isosurface pipeline instead of the built-in one.
    pub pipeline: Option<PathBuf>,
    pub fuse: bool,
}

/// The level-`level` isosurface of `volume` as a welded mesh (shared vertices,
/// gradient normals), by running the isosurface pipeline on the CPU backend.
pub fn isosurface(
    volume: Volume,
    request: &IsoRequest,
    library: &FunctorLibrary,
) -> Result<TriangleMesh, String> {
    let range = volume.value_range();
    let (triangles, _) = isosurface_triangles(volume, request, library)?;
    let mesh = triangles_to_mesh(&triangles, true).map_err(|e| format!("error: {}", e.0))?;
    if mesh.triangles.is_empty() {
        let range = range.map_or("no finite values".to_string(), |(lo, hi)| {
            format!("values {lo} to {hi}")
        });
        return Err(format!(
            "error: the level {} does not cross the volume ({range}); choose an --iso level inside that range",
            request.level
        ));
    }
    Ok(mesh)
}

/// The isosurface pipeline's `triangles` (Triangle records, none at all
/// being no error) and each triangle's cell (its `cells` output, numbered
/// over `volume`'s own cells): what a brick of a distributed volume needs to
/// keep its own triangles before they are welded.
pub fn isosurface_triangles(
    volume: Volume,
    request: &IsoRequest,
    library: &FunctorLibrary,
) -> Result<(Arc<dpp_runtime::Column>, Vec<u32>), String> {
    if !request.level.is_finite() {
        return Err(format!(
            "error: --iso {} is not a finite level",
            request.level
        ));
    }
    let options = CompileOptions {
        fuse: request.fuse,
        overrides: vec![("level".into(), format!("{:?}", request.level))],
    };
    let plan = match &request.pipeline {
        Some(path) => compile_file(path, library, &options),
        None => compile_text(
            Path::new("isosurface.dpp"),
            ISOSURFACE_PIPELINE,
            library,
            &options,
        ),
    }
    .map_err(|failure| failure.render(false))?;
    let uniforms = volume_uniforms(&volume);
    let resources = VolumeResources {
        volume: Arc::new(volume),
    };
    let context = RunContext {
        library,
        uniforms: &uniforms,
        resources: &resources,
        chunk: dpp_runtime::cpu::kernels::DEFAULT_CHUNK,
        column_pool: &ColumnPool::new(),
        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
    };
    let result = run_plan(&plan, &context).map_err(|e| format!("error: isosurface: {e}"))?;
    let array = |name: &str| match result.outputs.iter().find(|(n, _)| n == name) {
        Some((_, OutputValue::Array(array))) => Ok(array.clone()),
        _ => Err(format!(
            "error: the isosurface pipeline has no `{name}` output (an array)"
        )),
    };
    let (triangles, cells) = (array("triangles")?, array("cells")?);
    let cells = match cells.as_ref() {
        dpp_runtime::Column::U32(cells) if cells.len() == triangles.len() => cells.clone(),
        _ => {
            return Err(
                "error: the isosurface pipeline's `cells` output must be one u32 cell index per triangle"
                    .into(),
            )
        }
    };
    Ok((triangles, cells))
}

/// Colours the mesh by a second field: its value at each vertex, trilinearly
/// interpolated (clamped at the volume's border).
pub fn color_by(mesh: &mut TriangleMesh, field: &Volume) {
    let samples = mesh.positions.iter().map(|p| sample(field, *p)).collect();
    mesh.scalars = Some(samples);
}

fn sample(volume: &Volume, position: glam::Vec3) -> f32 {
    // Grid coordinates within this volume (a brick starts at sample `first`).
    let grid = ((position - volume.origin) / volume.spacing - volume.first.as_vec3())
        .max(glam::Vec3::ZERO);
    let last = (volume.dims - glam::UVec3::ONE).as_vec3();
    let grid = grid.min(last);
    let base = grid
        .floor()
        .as_uvec3()
        .min(volume.dims.saturating_sub(glam::UVec3::splat(2)));
    let t = grid - base.as_vec3();
    let mut value = 0.0;
    for corner in 0..8u32 {
        let offset = glam::UVec3::new(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
        let weight = glam::Vec3::select(
            offset.as_vec3().cmpeq(glam::Vec3::ONE),
            t,
            glam::Vec3::ONE - t,
        );
        let at = base + offset;
        value += weight.x * weight.y * weight.z * volume.value(at.x, at.y, at.z);
    }
    value
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec3, Vec3};

    #[test]
    fn trilinear_sampling_reproduces_a_linear_field() {
        let dims = UVec3::new(4, 5, 6);
        let mut volume = Volume {
            dims,
            spacing: Vec3::new(0.5, 1.0, 2.0),
            origin: Vec3::new(1.0, 0.0, -1.0),
            first: UVec3::ZERO,
            values: Vec::new(),
        };
        for k in 0..6 {
            for j in 0..5 {
                for i in 0..4 {
                    let p = volume.position(i, j, k);
                    volume.values.push(2.0 * p.x - p.y + 0.5 * p.z);
                }
            }
        }
        for p in [
            Vec3::new(1.3, 2.2, 3.1),
            Vec3::new(2.5, 4.0, 9.0),
            Vec3::new(1.0, 0.0, -1.0),
        ] {
            let expected = 2.0 * p.x - p.y + 0.5 * p.z;
            assert!(
                (sample(&volume, p) - expected).abs() < 1e-4,
                "{p}: {} vs {expected}",
                sample(&volume, p)
            );
        }
        // Outside, the border value: clamped, never extrapolated.
        assert!(
            (sample(&volume, Vec3::new(-5.0, 0.0, -1.0)) - (2.0 * 1.0 - 0.5 * 1.0)).abs() < 1e-4
        );
    }
}
