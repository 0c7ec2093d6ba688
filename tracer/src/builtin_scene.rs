//! A built-in procedural scene, so that the tracer runs without any input file:
//! the interface of a Richtmyer–Meshkov-like mixing layer.
//!
//! The field is `F(p) = z - h(x, y) - E(z) g(p)`: a plane `z = 0` displaced by
//! `h`, a multi-mode 2D perturbation (the classic random-phase initial condition of
//! an instability simulation) shaped into rounded bubbles between sharp spikes, and
//! by `g`, a 3D multi-mode term confined to the layer by the envelope `E`, that
//! folds the interface into overhangs and detached droplets. Its zero level set is meshed with naive surface nets. The layer faces
//! `+z`, towards the standard `front` camera. Every mode is a plane wave
//! `cos(k·p + φ) = Re(e^{i(kx x + φ)} e^{i ky y} e^{i kz z})`, so the field is
//! evaluated from per-axis tables of complex factors, which keeps generation fast.

use crate::mesh::TriangleMesh;
use crate::random::SplitMix64;
use fast_surface_nets::ndshape::RuntimeShape;
use fast_surface_nets::{surface_nets, SurfaceNetsBuffer};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::TAU;
use thiserror::Error;

/// Cells along x and y of the default scene (about 300K triangles).
pub const DEFAULT_RESOLUTION: u32 = 224;
pub const MIN_RESOLUTION: u32 = 8;
/// About 1.6M triangles; the sampled field then takes about 0.5 GB.
pub const MAX_RESOLUTION: u32 = 512;

/// The layer spans `[-1, 1]²` horizontally and `[-HALF_DEPTH, HALF_DEPTH]` in z.
const HALF_DEPTH: f32 = 0.45;
/// Height scale of the bubbles (in units of the perturbation's standard deviation).
const BUBBLE_HEIGHT: f32 = 0.14;
/// Total amplitude of the 3D modes.
const FOLDING: f32 = 0.12;
const SEED: u64 = 0x005e_ed2d_3df1_e1d5;
const INTERFACE_MODES: usize = 24;
const VOLUME_MODES: usize = 32;
/// Thickness of the envelope that confines the 3D modes to the layer.
const ENVELOPE_WIDTH: f32 = 0.18;

#[derive(Clone, Debug, Error, PartialEq, Eq)]
#[error("built-in scene resolution {0} is not in {MIN_RESOLUTION}..={MAX_RESOLUTION}")]
pub struct ResolutionOutOfRange(pub u32);

/// The built-in mixing-layer isosurface with `resolution` cells along x and y.
/// Per-vertex scalars are the interface displacement `z / HALF_DEPTH` in [-1, 1]
/// (negative in the spikes, positive on the bubbles), per-vertex normals the field
/// gradient. Deterministic: the same resolution gives the same mesh.
pub fn builtin_scene(resolution: u32) -> Result<TriangleMesh, ResolutionOutOfRange> {
    if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&resolution) {
        return Err(ResolutionOutOfRange(resolution));
    }
    let spacing = 2.0 / resolution as f32;
    let samples_xy = resolution + 1;
    let samples_z = (2.0 * HALF_DEPTH / spacing).ceil() as u32 + 1;
    let origin = Vec3::new(-1.0, -1.0, -HALF_DEPTH);
    let field = sample_field(samples_xy, samples_z, spacing, origin);

    let shape = RuntimeShape::<u32, 3>::new([samples_xy, samples_xy, samples_z]);
    let mut surface = SurfaceNetsBuffer::default();
    surface_nets(
        &field,
        &shape,
        [0; 3],
        [samples_xy - 1, samples_xy - 1, samples_z - 1],
        &mut surface,
    );

    let positions: Vec<Vec3> = surface
        .positions
        .iter()
        .map(|&p| origin + Vec3::from(p) * spacing)
        .collect();
    let normals = surface
        .normals
        .iter()
        .map(|&n| Vec3::from(n).normalize_or(Vec3::Z))
        .collect();
    let scalars = positions.iter().map(|p| p.z / HALF_DEPTH).collect();
    let triangles = surface
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    Ok(TriangleMesh {
        positions,
        triangles,
        normals: Some(normals),
        scalars: Some(scalars),
    })
}

/// A plane wave `amplitude · cos(k·p + phase)`.
struct Mode {
    wave_vector: Vec3,
    phase: f32,
    amplitude: f32,
}

/// Random-phase modes with wavenumbers in `[k_min, k_max]` and a spectrum falling
/// as `1/k`, scaled so that the amplitudes add up to `total_amplitude`.
fn random_modes(
    random: &mut SplitMix64,
    count: usize,
    k_min: f32,
    k_max: f32,
    vertical: bool,
    total_amplitude: f32,
) -> Vec<Mode> {
    let mut modes: Vec<Mode> = (0..count)
        .map(|_| {
            let k = k_min * (k_max / k_min).powf(random.next_f32());
            let azimuth = random.range(0.0, TAU);
            let elevation = if vertical {
                random.range(-1.0, 1.0).asin()
            } else {
                0.0
            };
            Mode {
                wave_vector: k * Vec3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                ),
                phase: random.range(0.0, TAU),
                amplitude: 1.0 / k,
            }
        })
        .collect();
    let sum: f32 = modes.iter().map(|m| m.amplitude).sum();
    for mode in &mut modes {
        mode.amplitude *= total_amplitude / sum;
    }
    modes
}

/// `e^{i (k x + φ)}` for each sample `x = origin + i * spacing`, as (re, im).
fn phasors(samples: u32, origin: f32, spacing: f32, k: f32, phase: f32) -> Vec<(f32, f32)> {
    (0..samples)
        .map(|i| {
            let angle = k * (origin + i as f32 * spacing) + phase;
            (angle.cos(), angle.sin())
        })
        .collect()
}

/// The field on a `samples_xy² × samples_z` lattice, x fastest (ndshape's order).
fn sample_field(samples_xy: u32, samples_z: u32, spacing: f32, origin: Vec3) -> Vec<f32> {
    let mut random = SplitMix64::new(SEED);
    let interface = random_modes(&mut random, INTERFACE_MODES, 7.0, 40.0, false, 1.0);
    let volume = random_modes(&mut random, VOLUME_MODES, 8.0, 50.0, true, FOLDING);
    let plane = (samples_xy * samples_xy) as usize;

    // h(x, y) per column, and the x·y factor of every volume mode per column.
    let mut height = vec![0.0f32; plane];
    let mut volume_xy = vec![(0.0f32, 0.0f32); plane * VOLUME_MODES];
    for mode in &interface {
        let along_x = phasors(
            samples_xy,
            origin.x,
            spacing,
            mode.wave_vector.x,
            mode.phase,
        );
        let along_y = phasors(samples_xy, origin.y, spacing, mode.wave_vector.y, 0.0);
        for (column, h) in height.iter_mut().enumerate() {
            let (xr, xi) = along_x[column % samples_xy as usize];
            let (yr, yi) = along_y[column / samples_xy as usize];
            *h += mode.amplitude * (xr * yr - xi * yi);
        }
    }
    // The late-time shape of the instability: rounded bubbles rising between sharp
    // spikes, i.e. |perturbation| (creases where it changes sign), shifted to mean ≈ 0.
    let deviation = (interface
        .iter()
        .map(|m| m.amplitude * m.amplitude)
        .sum::<f32>()
        / 2.0)
        .sqrt();
    for h in &mut height {
        *h = BUBBLE_HEIGHT * ((*h / deviation).abs() - 0.8);
    }
    for (m, mode) in volume.iter().enumerate() {
        let along_x = phasors(
            samples_xy,
            origin.x,
            spacing,
            mode.wave_vector.x,
            mode.phase,
        );
        let along_y = phasors(samples_xy, origin.y, spacing, mode.wave_vector.y, 0.0);
        for column in 0..plane {
            let (xr, xi) = along_x[column % samples_xy as usize];
            let (yr, yi) = along_y[column / samples_xy as usize];
            volume_xy[column * VOLUME_MODES + m] = (
                mode.amplitude * (xr * yr - xi * yi),
                mode.amplitude * (xr * yi + xi * yr),
            );
        }
    }

    let mut field = vec![0.0f32; plane * samples_z as usize];
    field
        .par_chunks_mut(plane)
        .enumerate()
        .for_each(|(layer, slice)| {
            let z = origin.z + layer as f32 * spacing;
            let envelope = (-(z / ENVELOPE_WIDTH).powi(2)).exp();
            let along_z: Vec<(f32, f32)> = volume
                .iter()
                .map(|mode| {
                    let angle = mode.wave_vector.z * z;
                    (envelope * angle.cos(), envelope * angle.sin())
                })
                .collect();
            for (column, value) in slice.iter_mut().enumerate() {
                let factors = &volume_xy[column * VOLUME_MODES..(column + 1) * VOLUME_MODES];
                let folding: f32 = factors
                    .iter()
                    .zip(&along_z)
                    .map(|(&(ar, ai), &(zr, zi))| ar * zr - ai * zi)
                    .sum();
                *value = z - height[column] - folding;
            }
        });
    field
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_scene_is_a_valid_deterministic_mesh() {
        let mesh = builtin_scene(32).unwrap();
        assert_eq!(mesh.validate(), Ok(()));
        assert!(mesh.triangles.len() > 1000, "{}", mesh.triangles.len());
        let bounds = mesh.bounds().unwrap();
        assert!(bounds.min.x >= -1.0 && bounds.max.x <= 1.0);
        assert!(bounds.min.z >= -HALF_DEPTH && bounds.max.z <= HALF_DEPTH);
        // The interface spans the layer horizontally.
        assert!(bounds.max.x - bounds.min.x > 1.8 && bounds.max.y - bounds.min.y > 1.8);
        let scalars = mesh.scalars.as_ref().unwrap();
        assert!(scalars.iter().all(|s| (-1.0..=1.0).contains(s)));
        assert_eq!(mesh, builtin_scene(32).unwrap());
    }

    #[test]
    fn resolution_is_checked() {
        assert_eq!(builtin_scene(2), Err(ResolutionOutOfRange(2)));
        assert_eq!(builtin_scene(5000), Err(ResolutionOutOfRange(5000)));
    }
}
