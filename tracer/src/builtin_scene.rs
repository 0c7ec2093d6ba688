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
//!
//! # Normals and the spikes' creases
//!
//! `h` is `|perturbation|`, so the interface has true creases (spikes) where the
//! perturbation changes sign: the field's gradient jumps there from one wall's
//! direction to the other's. Gradients estimated on the sampling lattice (what
//! surface nets provide) average the two walls over the cell that straddles the
//! crease, which gives the crease's vertices the bisector of the walls, a
//! direction the surface does not have; interpolated across the crease's
//! triangles, such normals sweep through every direction between the walls,
//! including the one a highlight needs, and the renderer drew bright dotted
//! lines along every crease. So the vertex normals are instead the field's exact
//! gradient at the vertex, taken on one side of the crease: each triangle takes
//! the side its corners are on on average (the sign of the sum of the
//! perturbation at its corners), and a vertex used from both sides is split in
//! two, one normal per side (the continuation of that side's smooth field). The
//! shading normal is then smooth on either side and turns at the crease as the
//! surface does.

use crate::mesh::TriangleMesh;
use dpp_runtime::random::SplitMix64;
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
/// gradient on the vertex's side of the spikes' creases (vertices on a crease are
/// split, see the module documentation). Deterministic: the same resolution gives
/// the same mesh.
pub fn builtin_scene(resolution: u32) -> Result<TriangleMesh, ResolutionOutOfRange> {
    if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&resolution) {
        return Err(ResolutionOutOfRange(resolution));
    }
    let modes = Modes::new();
    let (mut positions, indices) = lattice_surface(&modes, resolution);
    let gradients: Vec<Gradient> = positions.par_iter().map(|&p| modes.gradient(p)).collect();
    let mut normals: Vec<Vec3> = gradients.iter().map(|g| g.normal(g.side())).collect();
    // Each triangle takes the side of the crease its corners are on on average; a
    // corner whose vertex lies on the other side gets the vertex's twin on this
    // side.
    let mut twins: Vec<u32> = vec![u32::MAX; positions.len()];
    let mut triangles = Vec::with_capacity(indices.len() / 3);
    for corners in indices.chunks_exact(3) {
        let perturbation: f32 = corners
            .iter()
            .map(|&v| gradients[v as usize].perturbation)
            .sum();
        let side = side_of(perturbation);
        let mut triangle = [0u32; 3];
        for (slot, &vertex) in triangle.iter_mut().zip(corners) {
            let gradient = &gradients[vertex as usize];
            *slot = if gradient.side() == side {
                vertex
            } else {
                if twins[vertex as usize] == u32::MAX {
                    twins[vertex as usize] = positions.len() as u32;
                    positions.push(positions[vertex as usize]);
                    normals.push(gradient.normal(side));
                }
                twins[vertex as usize]
            };
        }
        triangles.push(triangle);
    }
    let scalars = positions.iter().map(|p| p.z / HALF_DEPTH).collect();
    Ok(TriangleMesh {
        positions,
        triangles,
        normals: Some(normals),
        scalars: Some(scalars),
    })
}

/// The zero level set of the field sampled with `resolution` cells along x and
/// y, by naive surface nets: vertex positions and triangle corners.
fn lattice_surface(modes: &Modes, resolution: u32) -> (Vec<Vec3>, Vec<u32>) {
    let spacing = 2.0 / resolution as f32;
    let samples_xy = resolution + 1;
    let samples_z = (2.0 * HALF_DEPTH / spacing).ceil() as u32 + 1;
    let origin = Vec3::new(-1.0, -1.0, -HALF_DEPTH);
    let field = sample_field(modes, samples_xy, samples_z, spacing, origin);

    let shape = RuntimeShape::<u32, 3>::new([samples_xy, samples_xy, samples_z]);
    let mut surface = SurfaceNetsBuffer::default();
    surface_nets(
        &field,
        &shape,
        [0; 3],
        [samples_xy - 1, samples_xy - 1, samples_z - 1],
        &mut surface,
    );
    let positions = surface
        .positions
        .iter()
        .map(|&p| origin + Vec3::from(p) * spacing)
        .collect();
    (positions, surface.indices)
}

/// `+1` or `-1`: the side of the spikes' creases where the interface
/// perturbation has this sign (`+1` for 0).
fn side_of(perturbation: f32) -> f32 {
    if perturbation < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// The modes of the scene's field (drawn from [`SEED`]).
struct Modes {
    /// The 2D modes of the interface perturbation `P(x, y)`.
    interface: Vec<Mode>,
    /// The 3D folding modes `g(p)`.
    volume: Vec<Mode>,
    /// The perturbation's standard deviation `σ`.
    deviation: f32,
}

/// The field's gradient at a point, in the two pieces that depend on the side of
/// the crease and the one that does not: `∇F = ẑ - side * crease - smooth`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Gradient {
    /// `P` at the point: its sign is the side of the crease.
    perturbation: f32,
    /// `BUBBLE_HEIGHT ∇P / σ`, the gradient of `h` up to the sign of `P`.
    crease: Vec3,
    /// `∇(E g)`, the folding's gradient.
    smooth: Vec3,
}

impl Gradient {
    fn side(&self) -> f32 {
        side_of(self.perturbation)
    }

    /// The unit normal `∇F / |∇F|` on `side` of the crease (`+z` where it vanishes).
    fn normal(&self, side: f32) -> Vec3 {
        (Vec3::Z - side * self.crease - self.smooth).normalize_or(Vec3::Z)
    }
}

impl Modes {
    fn new() -> Modes {
        let mut random = SplitMix64::new(SEED);
        let interface = random_modes(&mut random, INTERFACE_MODES, 7.0, 40.0, false, 1.0);
        let volume = random_modes(&mut random, VOLUME_MODES, 8.0, 50.0, true, FOLDING);
        let deviation = (interface
            .iter()
            .map(|m| m.amplitude * m.amplitude)
            .sum::<f32>()
            / 2.0)
            .sqrt();
        Modes {
            interface,
            volume,
            deviation,
        }
    }

    /// The field's gradient at `p`, evaluated from the modes (exact, unlike the
    /// lattice's differences).
    fn gradient(&self, p: Vec3) -> Gradient {
        let mut perturbation = 0.0;
        let mut perturbation_gradient = Vec3::ZERO;
        for mode in &self.interface {
            let (sin, cos) = (mode.wave_vector.dot(p) + mode.phase).sin_cos();
            perturbation += mode.amplitude * cos;
            perturbation_gradient -= mode.amplitude * sin * mode.wave_vector;
        }
        let envelope = (-(p.z / ENVELOPE_WIDTH).powi(2)).exp();
        let envelope_slope = -2.0 * p.z / (ENVELOPE_WIDTH * ENVELOPE_WIDTH) * envelope;
        let mut folding = 0.0;
        let mut folding_gradient = Vec3::ZERO;
        for mode in &self.volume {
            let (sin, cos) = (mode.wave_vector.dot(p) + mode.phase).sin_cos();
            folding += mode.amplitude * cos;
            folding_gradient -= mode.amplitude * sin * mode.wave_vector;
        }
        Gradient {
            perturbation,
            crease: BUBBLE_HEIGHT / self.deviation * perturbation_gradient,
            smooth: envelope * folding_gradient + Vec3::new(0.0, 0.0, envelope_slope * folding),
        }
    }
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
fn sample_field(
    modes: &Modes,
    samples_xy: u32,
    samples_z: u32,
    spacing: f32,
    origin: Vec3,
) -> Vec<f32> {
    let (interface, volume, deviation) = (&modes.interface, &modes.volume, modes.deviation);
    let plane = (samples_xy * samples_xy) as usize;

    // h(x, y) per column, and the x·y factor of every volume mode per column.
    let mut height = vec![0.0f32; plane];
    let mut volume_xy = vec![(0.0f32, 0.0f32); plane * VOLUME_MODES];
    for mode in interface {
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

    /// The interface perturbation `P(x, y)`, evaluated mode by mode.
    fn perturbation_at(modes: &Modes, p: Vec3) -> f32 {
        (modes.interface.iter())
            .map(|m| m.amplitude * (m.wave_vector.dot(p) + m.phase).cos())
            .sum()
    }

    /// The field `F(p) = z - B (|P| / σ - 0.8) - E(z) g(p)` evaluated mode by
    /// mode, with `|P|` taken as `side * P`: `side = sign(P)` gives the field
    /// itself, the other sign the smooth continuation of the far side of a crease.
    fn field_on_side(modes: &Modes, p: Vec3, side: f32) -> f32 {
        let folding: f32 = (modes.volume.iter())
            .map(|m| m.amplitude * (m.wave_vector.dot(p) + m.phase).cos())
            .sum();
        let envelope = (-(p.z / ENVELOPE_WIDTH).powi(2)).exp();
        let height = BUBBLE_HEIGHT * (side * perturbation_at(modes, p) / modes.deviation - 0.8);
        p.z - height - envelope * folding
    }

    /// The unit gradient of [`field_on_side`] by central differences.
    fn numeric_normal(modes: &Modes, p: Vec3, side: f32) -> Vec3 {
        let step = 1e-3;
        let difference = |axis: Vec3| {
            (field_on_side(modes, p + step * axis, side)
                - field_on_side(modes, p - step * axis, side))
                / (2.0 * step)
        };
        Vec3::new(
            difference(Vec3::X),
            difference(Vec3::Y),
            difference(Vec3::Z),
        )
        .normalize()
    }

    /// Angle in degrees between two unit vectors.
    fn degrees(a: Vec3, b: Vec3) -> f32 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn the_sampled_field_is_the_modes_field() {
        // The lattice (complex factor tables) and the mode-by-mode evaluation agree,
        // so the normals below belong to the surface that is meshed.
        let modes = Modes::new();
        let (resolution, samples_z) = (16u32, 4u32);
        let spacing = 2.0 / resolution as f32;
        let origin = Vec3::new(-1.0, -1.0, -0.1);
        let field = sample_field(&modes, resolution + 1, samples_z, spacing, origin);
        let samples = resolution as usize + 1;
        for (index, &value) in field.iter().enumerate().step_by(7) {
            let (x, y, z) = (
                index % samples,
                index / samples % samples,
                index / samples / samples,
            );
            let p = origin + spacing * Vec3::new(x as f32, y as f32, z as f32);
            let side = side_of(perturbation_at(&modes, p));
            let expected = field_on_side(&modes, p, side);
            assert!(
                (value - expected).abs() < 1e-4,
                "{p}: {value} vs {expected}"
            );
        }
    }

    #[test]
    fn gradients_match_finite_differences_on_either_side() {
        let modes = Modes::new();
        let mut random = SplitMix64::new(7);
        for _ in 0..200 {
            let p = Vec3::new(
                random.range(-1.0, 1.0),
                random.range(-1.0, 1.0),
                random.range(-0.3, 0.3),
            );
            let gradient = modes.gradient(p);
            assert!((gradient.perturbation - perturbation_at(&modes, p)).abs() < 1e-4);
            for side in [-1.0, 1.0] {
                let error = degrees(gradient.normal(side), numeric_normal(&modes, p, side));
                assert!(error < 0.2, "{p}, side {side}: {error} degrees");
            }
        }
    }

    #[test]
    fn normals_do_not_sweep_across_the_spikes_creases() {
        // The spikes' creases (P = 0) are sharp. Normals from the sampling lattice
        // averaged the two walls at a crease's vertices, so across a crease the
        // interpolated normal swept through directions the surface does not have
        // (37 degrees off the nearer wall's normal on average at this resolution,
        // 59 at the 90th percentile), and the highlight that some of them catch
        // drew bright dotted lines along the creases. Each triangle's normals must
        // now be those of one side.
        let modes = Modes::new();
        let mesh = builtin_scene(64).unwrap();
        let normals = mesh.normals.as_ref().unwrap();
        let mut errors = Vec::new();
        for &[a, b, c] in &mesh.triangles {
            let corners = [a, b, c].map(|v| mesh.positions[v as usize]);
            let signs = corners.map(|p| perturbation_at(&modes, p) < 0.0);
            if signs.iter().all(|&s| s == signs[0]) {
                continue;
            }
            let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
            let interpolated =
                (normals[a as usize] + normals[b as usize] + normals[c as usize]).normalize();
            let error = [-1.0, 1.0]
                .map(|side| degrees(interpolated, numeric_normal(&modes, centroid, side)))
                .into_iter()
                .fold(f32::INFINITY, f32::min);
            errors.push(error);
        }
        assert!(
            errors.len() > 1000,
            "{} triangles across creases",
            errors.len()
        );
        errors.sort_by(f32::total_cmp);
        let mean = errors.iter().sum::<f32>() / errors.len() as f32;
        let ninetieth = errors[errors.len() * 9 / 10];
        assert!(
            mean < 3.0 && ninetieth < 6.0,
            "mean {mean}, 90th percentile {ninetieth} degrees"
        );
    }

    #[test]
    fn crease_vertices_are_split_not_moved() {
        // The same triangles at the same places; only vertices on a crease are
        // duplicated, each copy with the normal of one side.
        let modes = Modes::new();
        let (positions, indices) = lattice_surface(&modes, 32);
        let mesh = builtin_scene(32).unwrap();
        assert_eq!(mesh.triangles.len() * 3, indices.len());
        for (triangle, corners) in mesh.triangles.iter().zip(indices.chunks_exact(3)) {
            for (&split, &original) in triangle.iter().zip(corners) {
                assert_eq!(mesh.positions[split as usize], positions[original as usize]);
            }
        }
        let twins = mesh.positions.len() - positions.len();
        assert!(
            twins > 0 && twins < positions.len() / 4,
            "{twins} of {}",
            positions.len()
        );
        let normals = mesh.normals.as_ref().unwrap();
        assert!(normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-5));
    }

    #[test]
    fn resolution_is_checked() {
        assert_eq!(builtin_scene(2), Err(ResolutionOutOfRange(2)));
        assert_eq!(builtin_scene(5000), Err(ResolutionOutOfRange(5000)));
    }
}
