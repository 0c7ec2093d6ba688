//! The paper's data sets, reproduced procedurally, and simple fields for tests.
//!
//! Every generated volume spans the world box `[-1, 1]³` whatever its
//! dimensions (so a 400×400×256 grid has flatter cells than a 256³ one, and the
//! same field sampled more or less finely), and is deterministic: the same
//! dimensions give the same values on every run, whatever the thread count.
//! Samples are computed in parallel over z slices.
//!
//! - [`richtmyer_meshkov`]: a mixing layer like LLNL's Richtmyer–Meshkov
//!   instability data set (the paper's "RM"), a mixing fraction in [0, 255];
//!   isosurface at [`RM_DEFAULT_LEVEL`].
//! - [`lead_telluride`]: a charge-density-like field of a rock-salt PbTe crystal
//!   (the paper's "lead telluride"); isosurface at [`PBTE_DEFAULT_LEVEL`].
//! - [`sphere`], [`plane`]: signed distances (level 0) for testing meshing.

use super::{sample_count, Brick, Volume, VolumeError, MAX_SAMPLES};
use dpp_runtime::random::SplitMix64;
use glam::{UVec3, Vec3};
use rayon::prelude::*;
use std::f32::consts::TAU;

/// The isovalue of the RM mixing fraction that shows the interface between the
/// two fluids (half way between pure light fluid, 0, and pure heavy fluid, 255).
pub const RM_DEFAULT_LEVEL: f32 = 128.0;
/// The isovalue of the PbTe field that shows atoms (large Pb, smaller Te)
/// joined by thin bonds. Peaks: 1.0 at Pb, 0.8 at Te; bonds reach about 0.43.
pub const PBTE_DEFAULT_LEVEL: f32 = 0.3;
/// Level of the signed-distance fields ([`sphere`], [`plane`]).
pub const DISTANCE_LEVEL: f32 = 0.0;
/// Radius of `by_name("sphere")`'s sphere.
pub const DEFAULT_SPHERE_RADIUS: f32 = 0.75;

/// A named data set for [`by_name`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dataset {
    RichtmyerMeshkov,
    LeadTelluride,
    Sphere,
}

/// Names [`by_name`] accepts, aliases included.
pub const NAMES: &[&str] = &[
    "rm",
    "richtmyer-meshkov",
    "pbte",
    "lead-telluride",
    "sphere",
];

impl Dataset {
    pub fn from_name(name: &str) -> Result<Dataset, VolumeError> {
        match name.to_ascii_lowercase().as_str() {
            "rm" | "richtmyer-meshkov" => Ok(Dataset::RichtmyerMeshkov),
            "pbte" | "lead-telluride" => Ok(Dataset::LeadTelluride),
            "sphere" => Ok(Dataset::Sphere),
            _ => {
                let lower = name.to_ascii_lowercase();
                let suggestion = NAMES
                    .iter()
                    .map(|&known| (known, strsim::jaro_winkler(&lower, known)))
                    .filter(|&(_, score)| score > 0.7)
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(known, _)| known);
                Err(VolumeError::UnknownVolume {
                    name: name.to_string(),
                    suggestion,
                    known: NAMES,
                })
            }
        }
    }

    /// The isovalue that shows the data set's interesting surface.
    pub fn default_level(self) -> f32 {
        match self {
            Dataset::RichtmyerMeshkov => RM_DEFAULT_LEVEL,
            Dataset::LeadTelluride => PBTE_DEFAULT_LEVEL,
            Dataset::Sphere => DISTANCE_LEVEL,
        }
    }

    /// Generates the data set on a `dims` grid (checked: at least 2 samples per
    /// axis, at most [`MAX_SAMPLES`]).
    pub fn generate(self, dims: UVec3) -> Result<Volume, VolumeError> {
        self.generate_box(dims, [UVec3::ZERO, dims])
    }

    /// The samples of `brick` (its `samples` box, ghost layers included) of
    /// the data set on a `dims` grid: bit for bit the same sub-box of
    /// [`Dataset::generate`]'s volume, with `first` the box's lowest sample.
    pub fn generate_brick(self, dims: UVec3, brick: &Brick) -> Result<Volume, VolumeError> {
        self.generate_box(dims, brick.samples)
    }

    /// The samples `[samples[0], samples[1])` of the data set on a `dims` grid.
    /// Every generator is a pointwise function of the global sample index (and
    /// of `dims`, which sets the spacing), so any box is the same as that box
    /// of the whole volume, bit for bit.
    pub fn generate_box(self, dims: UVec3, samples: [UVec3; 2]) -> Result<Volume, VolumeError> {
        if dims.cmplt(UVec3::splat(2)).any() {
            return Err(VolumeError::BadGenerateDims {
                dims,
                what: "at least 2 samples are needed along each axis",
            });
        }
        if sample_count(dims.as_u64vec3().to_array()) > MAX_SAMPLES {
            return Err(VolumeError::BadGenerateDims {
                dims,
                what: "too many samples (at most 2^31)",
            });
        }
        if samples[0].cmpgt(samples[1]).any() || samples[1].cmpgt(dims).any() {
            return Err(VolumeError::BadGenerateDims {
                dims,
                what: "the box of samples asked for is not inside the grid",
            });
        }
        let grid = Grid { dims, samples };
        Ok(match self {
            Dataset::RichtmyerMeshkov => RichtmyerMeshkov::default().generate_in(grid),
            Dataset::LeadTelluride => lead_telluride_in(grid),
            Dataset::Sphere => sphere_in(grid, DEFAULT_SPHERE_RADIUS),
        })
    }
}

/// The data set called `name` (see [`NAMES`]) on a `dims` grid; an unknown name
/// gives an error listing the known ones, with a suggestion when one is close.
pub fn by_name(name: &str, dims: UVec3) -> Result<Volume, VolumeError> {
    Dataset::from_name(name)?.generate(dims)
}

/// The box `[samples[0], samples[1])` of a `dims` grid over `[-1, 1]³`.
#[derive(Clone, Copy, Debug)]
struct Grid {
    dims: UVec3,
    samples: [UVec3; 2],
}

impl Grid {
    fn whole(dims: UVec3) -> Grid {
        Grid {
            dims,
            samples: [UVec3::ZERO, dims],
        }
    }

    /// World coordinates of the box's samples along `axis` (global indices).
    fn coordinates(&self, axis: usize) -> Vec<f32> {
        let step = 2.0 / (self.dims[axis].max(2) - 1) as f32;
        (self.samples[0][axis]..self.samples[1][axis])
            .map(|i| -1.0 + step * i as f32)
            .collect()
    }
}

/// The box of a `dims` volume over `[-1, 1]³`, filled one z slice at a time in
/// parallel by `fill(k, z, slice)` (`slice` is x fastest; `k` the slice's
/// index in the box, `z` its world coordinate, from its global index).
/// Dimensions below 2 give a single sample at -1 along that axis.
fn unit_cube(grid: Grid, fill: impl Fn(usize, f32, &mut [f32]) + Sync) -> Volume {
    let dims = grid.dims;
    let spacing = Vec3::from_array(dims.to_array().map(|n| 2.0 / (n.max(2) - 1) as f32));
    let origin = Vec3::splat(-1.0);
    let local = grid.samples[1].saturating_sub(grid.samples[0]);
    let zs = grid.coordinates(2);
    let plane = local.x as usize * local.y as usize;
    let mut values = vec![0.0f32; plane * local.z as usize];
    if plane > 0 {
        values
            .par_chunks_mut(plane)
            .enumerate()
            .for_each(|(k, slice)| fill(k, zs[k], slice));
    }
    Volume {
        dims: local,
        spacing,
        origin,
        first: grid.samples[0],
        values,
    }
}

/// `|p| - radius` over `[-1, 1]³`: negative inside a sphere at the centre.
pub fn sphere(dims: UVec3, radius: f32) -> Volume {
    sphere_in(Grid::whole(dims), radius)
}

fn sphere_in(grid: Grid, radius: f32) -> Volume {
    let (xs, ys) = (grid.coordinates(0), grid.coordinates(1));
    unit_cube(grid, |_, z, slice| {
        for (row, y) in slice.chunks_exact_mut(xs.len()).zip(&ys) {
            for (value, x) in row.iter_mut().zip(&xs) {
                *value = Vec3::new(*x, *y, z).length() - radius;
            }
        }
    })
}

/// `p · n̂ - offset` over `[-1, 1]³` (`n̂` is `normal` normalised; a zero normal
/// means +z): negative on the side opposite `normal`.
pub fn plane(dims: UVec3, normal: Vec3, offset: f32) -> Volume {
    let n = normal.normalize_or(Vec3::Z);
    let grid = Grid::whole(dims);
    let (xs, ys) = (grid.coordinates(0), grid.coordinates(1));
    unit_cube(grid, |_, z, slice| {
        for (row, y) in slice.chunks_exact_mut(xs.len()).zip(&ys) {
            for (value, x) in row.iter_mut().zip(&xs) {
                *value = Vec3::new(*x, *y, z).dot(n) - offset;
            }
        }
    })
}

// ---------------------------------------------------------------------------
// Richtmyer–Meshkov

/// Parameters of the RM mixing layer. [`richtmyer_meshkov`] uses the defaults.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RichtmyerMeshkov {
    /// How far the mixing has developed, from 0 (a flat interface) to about 1.5;
    /// default 1. The bubbles' height, the layer's thickness and the amplitude of
    /// its turbulent folding grow in proportion.
    pub mixing: f32,
    pub seed: u64,
}

impl Default for RichtmyerMeshkov {
    fn default() -> Self {
        RichtmyerMeshkov {
            mixing: 1.0,
            seed: 0x5eed_4d1c_0de5_0001,
        }
    }
}

/// Height scale of the bubbles (world units, at mixing 1).
const RM_BUBBLE_HEIGHT: f32 = 0.12;
/// Half thickness of the turbulent layer (at mixing 1).
const RM_LAYER: f32 = 0.6;
/// Amplitude of the turbulent folding (at mixing 1), in units of the field's
/// standard deviation.
const RM_FOLDING: f32 = 1.5;
/// Modes and wavenumbers (radians per world unit) of the interface's 2D
/// perturbation and of the 3D folding. The shortest wavelength, 2π/72 ≈ 0.087,
/// is 5.5 cells of a 128³ grid.
const RM_INTERFACE_MODES: usize = 24;
const RM_INTERFACE_K: (f32, f32) = (5.0, 30.0);
const RM_FOLDING_MODES: usize = 64;
const RM_FOLDING_K: (f32, f32) = (14.0, 72.0);
/// Half width of the diffuse interface (world units): the mixing fraction goes
/// from 0 to 255 over `d ∈ [-RM_DIFFUSION, RM_DIFFUSION]` of the displaced height.
const RM_DIFFUSION: f32 = 0.05;

/// A Richtmyer–Meshkov-like mixing layer (see [`RichtmyerMeshkov`]).
///
/// The heavy fluid (255) lies above a horizontal interface at `z ≈ 0`, the light
/// one (0) below. The interface is displaced by `h(x, y)`, a random-phase
/// multi-mode 2D perturbation (the classic initial condition of an instability
/// simulation) shaped into rounded bubbles rising between sharp spikes
/// (`|n| - c`, creased where `n` changes sign). Around it, a 3D multi-mode
/// "turbulence" `t` confined to the layer by a smooth envelope `E` folds the
/// interface into overhangs, fingers and detached droplets, most
/// strongly in the middle of the layer: the height above the interface becomes
/// `d = z - h - A E(z - h) t`, and the mixing fraction is `255 S(d)`, a smooth
/// step from 0 to 255 over `|d| < RM_DIFFUSION`. Isovalues other than
/// [`RM_DEFAULT_LEVEL`] give nearby versions of the same surface.
///
/// Every mode is a plane wave `a cos(k·p + φ)`, evaluated as the real part of a
/// product of per-axis tables of complex factors: about 64 multiply-adds per
/// sample inside the layer and none outside it.
pub fn richtmyer_meshkov(dims: UVec3) -> Volume {
    RichtmyerMeshkov::default().generate(dims)
}

impl RichtmyerMeshkov {
    pub fn generate(&self, dims: UVec3) -> Volume {
        self.generate_in(Grid::whole(dims))
    }

    /// The box `[samples[0], samples[1])` of [`RichtmyerMeshkov::generate`]'s
    /// `dims` volume, bit for bit (the field is a pointwise function of the
    /// global sample index). The box must lie inside the grid.
    pub fn generate_box(&self, dims: UVec3, samples: [UVec3; 2]) -> Volume {
        self.generate_in(Grid { dims, samples })
    }

    fn generate_in(&self, grid: Grid) -> Volume {
        let mut random = SplitMix64::new(self.seed);
        let interface = Modes::random(&mut random, RM_INTERFACE_MODES, RM_INTERFACE_K, false);
        let folding = Modes::random(&mut random, RM_FOLDING_MODES, RM_FOLDING_K, true);
        let mixing = self.mixing.max(0.0);
        let (xs, ys, zs) = (
            grid.coordinates(0),
            grid.coordinates(1),
            grid.coordinates(2),
        );

        // h(x, y) per column: bubbles and spikes.
        let interface_x = interface.phasors(&xs, 0, true);
        let interface_y = interface.phasors(&ys, 1, false);
        let bubble = RM_BUBBLE_HEIGHT * mixing;
        let heights: Vec<f32> = (0..xs.len() * ys.len())
            .into_par_iter()
            .map(|column| {
                let (i, j) = (column % xs.len(), column / xs.len());
                let n = interface_x.row(i).dot_real(&interface_y.row(j));
                bubble * (n.abs() - 0.8)
            })
            .collect();

        let layer = RM_LAYER * mixing.max(1e-3);
        let amplitude = RM_FOLDING * mixing;
        let folding_x = folding.phasors(&xs, 0, true);
        let folding_y = folding.phasors(&ys, 1, false);
        let folding_z = folding.phasors(&zs, 2, false);
        unit_cube(grid, |k, z, slice| {
            let along_z = folding_z.row(k);
            for (j, (row, row_heights)) in slice
                .chunks_exact_mut(xs.len())
                .zip(heights.chunks_exact(xs.len()))
                .enumerate()
            {
                // The y·z factor of every mode, for this row.
                let yz = folding_y.row(j).times(&along_z);
                for (i, (value, &h)) in row.iter_mut().zip(row_heights).enumerate() {
                    let s = z - h;
                    let u = s / layer;
                    let d = if u.abs() < 1.0 && amplitude > 0.0 {
                        let envelope = (1.0 - u * u) * (1.0 - u * u);
                        s - amplitude * envelope * folding_x.row(i).dot_real(&yz.row())
                    } else {
                        s
                    };
                    let t = (0.5 + 0.5 * d / RM_DIFFUSION).clamp(0.0, 1.0);
                    *value = (255.0 * t * t * t * (t * (t * 6.0 - 15.0) + 10.0)).min(255.0);
                }
            }
        })
    }
}

/// Lanes of the mode sums (mode counts are multiples of it, for vectorisation).
const LANES: usize = 8;

/// Random-phase plane waves `a cos(k·p + φ)` whose amplitudes fall as `1/k` and
/// are normalised so that the sum has a standard deviation of 1.
struct Modes {
    wave_vectors: Vec<Vec3>,
    phases: Vec<f32>,
    amplitudes: Vec<f32>,
}

impl Modes {
    /// `count` modes with wavenumbers log-uniform in `k`, directions uniform on
    /// the sphere (`volume`) or on the horizontal circle.
    fn random(random: &mut SplitMix64, count: usize, k: (f32, f32), volume: bool) -> Modes {
        debug_assert_eq!(count % LANES, 0);
        let mut modes = Modes {
            wave_vectors: Vec::with_capacity(count),
            phases: Vec::with_capacity(count),
            amplitudes: Vec::with_capacity(count),
        };
        for _ in 0..count {
            let wavenumber = k.0 * (k.1 / k.0).powf(random.next_f32());
            let azimuth = random.range(0.0, TAU);
            let elevation = if volume {
                random.range(-1.0, 1.0).asin()
            } else {
                0.0
            };
            modes.wave_vectors.push(
                wavenumber
                    * Vec3::new(
                        elevation.cos() * azimuth.cos(),
                        elevation.cos() * azimuth.sin(),
                        elevation.sin(),
                    ),
            );
            modes.phases.push(random.range(0.0, TAU));
            modes.amplitudes.push(1.0 / wavenumber);
        }
        // The variance of a sum of random-phase cosines is Σ a² / 2.
        let deviation = (modes.amplitudes.iter().map(|a| a * a).sum::<f32>() / 2.0).sqrt();
        for a in &mut modes.amplitudes {
            *a /= deviation;
        }
        modes
    }

    /// For each coordinate, `e^{i k_axis c}` of every mode, times the amplitude
    /// and `e^{i φ}` when `first`.
    fn phasors(&self, coordinates: &[f32], axis: usize, first: bool) -> PhasorTable {
        let count = self.phases.len();
        let mut table = PhasorTable {
            count,
            re: Vec::with_capacity(coordinates.len() * count),
            im: Vec::with_capacity(coordinates.len() * count),
        };
        for &c in coordinates {
            for m in 0..count {
                let mut angle = self.wave_vectors[m][axis] * c;
                let mut scale = 1.0;
                if first {
                    angle += self.phases[m];
                    scale = self.amplitudes[m];
                }
                table.re.push(scale * angle.cos());
                table.im.push(scale * angle.sin());
            }
        }
        table
    }
}

/// Complex factors per coordinate and mode.
struct PhasorTable {
    count: usize,
    re: Vec<f32>,
    im: Vec<f32>,
}

impl PhasorTable {
    fn row(&self, index: usize) -> PhasorRow<'_> {
        let range = index * self.count..(index + 1) * self.count;
        PhasorRow {
            re: &self.re[range.clone()],
            im: &self.im[range],
        }
    }
}

struct PhasorRow<'a> {
    re: &'a [f32],
    im: &'a [f32],
}

/// Owned complex factors per mode.
struct Phasors {
    re: Vec<f32>,
    im: Vec<f32>,
}

impl Phasors {
    fn row(&self) -> PhasorRow<'_> {
        PhasorRow {
            re: &self.re,
            im: &self.im,
        }
    }
}

impl PhasorRow<'_> {
    /// The mode-wise product with `other`.
    fn times(&self, other: &PhasorRow) -> Phasors {
        let (mut re, mut im) = (
            Vec::with_capacity(self.re.len()),
            Vec::with_capacity(self.re.len()),
        );
        for m in 0..self.re.len() {
            re.push(self.re[m] * other.re[m] - self.im[m] * other.im[m]);
            im.push(self.re[m] * other.im[m] + self.im[m] * other.re[m]);
        }
        Phasors { re, im }
    }

    /// `Re Σ_m self_m · other_m`, summed in `LANES` independent lanes (so that it
    /// vectorises) combined in a fixed order.
    fn dot_real(&self, other: &PhasorRow) -> f32 {
        let mut lanes = [0.0f32; LANES];
        for (((ar, ai), br), bi) in self
            .re
            .chunks_exact(LANES)
            .zip(self.im.chunks_exact(LANES))
            .zip(other.re.chunks_exact(LANES))
            .zip(other.im.chunks_exact(LANES))
        {
            for l in 0..LANES {
                lanes[l] += ar[l] * br[l] - ai[l] * bi[l];
            }
        }
        lanes.iter().sum()
    }
}

// ---------------------------------------------------------------------------
// ---------------------------------------------------------------------------
// Lead telluride

/// Unit cells of the crystal along each axis of `[-1, 1]³`.
pub const PBTE_UNIT_CELLS: u32 = 4;
const PB_PEAK: f32 = 1.0;
const TE_PEAK: f32 = 0.8;
const BOND_PEAK: f32 = 0.35;
/// Gaussian widths in units of the Pb–Te distance (half the lattice constant).
const PB_SIGMA: f32 = 0.22;
const TE_SIGMA: f32 = 0.16;
const BOND_SIGMA: f32 = 0.08;

/// A charge-density-like field of lead telluride, a rock-salt crystal: Pb and Te
/// alternate on a simple cubic lattice of spacing `a/2` (Pb at the FCC sites
/// `(0,0,0), (½,½,0), …`, Te at `(½,0,0), …`), [`PBTE_UNIT_CELLS`] unit cells across
/// `[-1, 1]³` with Pb at the corners, so the field is periodic over the box.
/// Each Pb site is a Gaussian of peak 1.0, each Te a narrower one of peak 0.8,
/// and every Pb–Te pair is joined by a thin Gaussian bond along the cube axes
/// (peak 0.35 half way, falling as `sin²` to 0 at the atoms). At [`PBTE_DEFAULT_LEVEL`] atoms of two sizes appear joined by
/// thin tubes.
pub fn lead_telluride(dims: UVec3) -> Volume {
    lead_telluride_in(Grid::whole(dims))
}

fn lead_telluride_in(grid: Grid) -> Volume {
    let sites = 2.0 * PBTE_UNIT_CELLS as f32;
    // Lattice coordinate q in [0, sites] along each axis, and per sample the
    // 1D factors of the Gaussians of the two surrounding sites and of the
    // nearest bond line.
    struct AxisFactors {
        /// Index of the lower surrounding site.
        site: u32,
        pb: [f32; 2],
        te: [f32; 2],
        /// Across a bond line: a Gaussian of the distance to the nearest one.
        bond: f32,
        /// Along a bond line: `sin²(π q)`, 0 at the atoms, 1 half way.
        along: f32,
    }
    let factors = |axis: usize| -> Vec<AxisFactors> {
        grid.coordinates(axis)
            .into_iter()
            .map(|c| {
                let q = (c + 1.0) * 0.5 * sites;
                let site = (q.floor().max(0.0) as u32).min(sites as u32 - 1);
                let gauss = |d: f32, sigma: f32| (-d * d / (2.0 * sigma * sigma)).exp();
                let d = [q - site as f32, q - site as f32 - 1.0];
                let nearest = q - q.round();
                AxisFactors {
                    site,
                    pb: d.map(|d| gauss(d, PB_SIGMA)),
                    te: d.map(|d| gauss(d, TE_SIGMA)),
                    bond: gauss(nearest, BOND_SIGMA),
                    along: (std::f32::consts::PI * q).sin().powi(2),
                }
            })
            .collect()
    };
    let (fx, fy) = (factors(0), factors(1));
    let fz = factors(2);
    unit_cube(grid, |k, _, slice| {
        let az = &fz[k];
        for (row, ay) in slice.chunks_exact_mut(fx.len()).zip(&fy) {
            for (value, ax) in row.iter_mut().zip(&fx) {
                let mut density = 0.0;
                for cz in 0..2 {
                    for cy in 0..2 {
                        for cx in 0..2 {
                            let parity = (ax.site + ay.site + az.site) as usize + cx + cy + cz;
                            density += if parity & 1 == 0 {
                                PB_PEAK * ax.pb[cx] * ay.pb[cy] * az.pb[cz]
                            } else {
                                TE_PEAK * ax.te[cx] * ay.te[cy] * az.te[cz]
                            };
                        }
                    }
                }
                // Bond lines along x lie at whole y and z lattice coordinates, etc.
                density += BOND_PEAK
                    * (ax.along * ay.bond * az.bond
                        + ay.along * ax.bond * az.bond
                        + az.along * ax.bond * ay.bond);
                *value = density;
            }
        }
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn sphere_and_plane_are_signed_distances() {
        let v = sphere(UVec3::new(5, 9, 3), 0.5);
        assert_eq!(v.dims, UVec3::new(5, 9, 3));
        assert_eq!(v.bounds().min, Vec3::splat(-1.0));
        assert!((v.bounds().max - Vec3::ONE).length() < 1e-6);
        assert!((v.value(2, 4, 1) + 0.5).abs() < 1e-6);
        assert!((v.value(4, 8, 2) - (3f32.sqrt() - 0.5)).abs() < 1e-5);
        assert_eq!(v.values.len(), 5 * 9 * 3);

        let p = plane(UVec3::new(3, 3, 3), Vec3::new(0.0, 0.0, 2.0), 0.25);
        assert!((p.value(0, 0, 0) + 1.25).abs() < 1e-6);
        assert!((p.value(2, 1, 2) - 0.75).abs() < 1e-6);
        assert!((p.gradient(1, 1, 1) - Vec3::Z).length() < 1e-5);
        // A plane crosses one layer of cells.
        let p = plane(UVec3::new(8, 8, 8), Vec3::Z, 0.1);
        assert_eq!(p.crossing_cell_count(0.0), 49);
    }

    #[test]
    fn rm_is_a_deterministic_convoluted_mixing_layer() {
        let dims = UVec3::new(40, 36, 32);
        let v = richtmyer_meshkov(dims);
        assert!(v.validate().is_ok());
        assert_eq!(v, richtmyer_meshkov(dims));
        let (lo, hi) = v.value_range().unwrap();
        assert!(
            (0.0..1.0).contains(&lo) && hi <= 255.0 && hi > 254.0,
            "{lo} {hi}"
        );
        // Light fluid at the bottom, heavy at the top.
        assert!(v.value(5, 5, 0) < 1.0 && v.value(5, 5, 31) > 254.0);
        // Far more convoluted than a flat interface (which crosses 39 × 35 cells).
        let crossed = v.crossing_cell_count(RM_DEFAULT_LEVEL);
        assert!(crossed > 3 * 39 * 35, "{crossed}");
        // A flat interface without mixing.
        let flat = RichtmyerMeshkov {
            mixing: 0.0,
            ..Default::default()
        }
        .generate(dims);
        assert_eq!(flat.crossing_cell_count(RM_DEFAULT_LEVEL), 39 * 35);
    }

    #[test]
    fn pbte_is_a_periodic_crystal_of_two_atoms() {
        // 4 unit cells = 8 site spacings over 33 samples: 4 samples per spacing.
        let v = lead_telluride(UVec3::splat(33));
        assert!(v.validate().is_ok());
        let pb = v.value(0, 0, 0);
        let te = v.value(4, 0, 0);
        assert!(
            (pb - 1.0).abs() < 0.1 && (te - 0.8).abs() < 0.1,
            "{pb} {te}"
        );
        assert_eq!(v.value(8, 8, 0), pb, "Pb on face centres");
        assert_eq!(v.value(4, 4, 4), te, "Te at the body centre");
        // Periodic: the opposite faces are equal.
        for j in 0..33 {
            for i in 0..33 {
                assert!((v.value(i, j, 0) - v.value(i, j, 32)).abs() < 1e-6);
                assert!((v.value(0, i, j) - v.value(32, i, j)).abs() < 1e-6);
            }
        }
        // Bond midpoints are above the level, cube-face centres between bonds
        // far below.
        assert!(v.value(2, 0, 0) > PBTE_DEFAULT_LEVEL);
        assert!(v.value(2, 2, 0) < 0.1);
        assert!(v.crossing_cell_count(PBTE_DEFAULT_LEVEL) > 1000);
    }

    #[test]
    fn by_name_knows_aliases_and_suggests() {
        let dims = UVec3::splat(6);
        assert_eq!(by_name("rm", dims).unwrap(), richtmyer_meshkov(dims));
        assert_eq!(
            by_name("Richtmyer-Meshkov", dims).unwrap(),
            richtmyer_meshkov(dims)
        );
        assert_eq!(
            by_name("lead-telluride", dims).unwrap(),
            lead_telluride(dims)
        );
        assert_eq!(by_name("pbte", dims).unwrap(), lead_telluride(dims));
        assert_eq!(
            by_name("sphere", dims).unwrap(),
            sphere(dims, DEFAULT_SPHERE_RADIUS)
        );
        let message = by_name("sphre", dims).unwrap_err().to_string();
        assert_eq!(
            message,
            "unknown volume 'sphre' (did you mean 'sphere'?); known volumes: rm, richtmyer-meshkov, pbte, lead-telluride, sphere"
        );
        let message = by_name("lead-tellurid", dims).unwrap_err().to_string();
        assert!(
            message.contains("did you mean 'lead-telluride'"),
            "{message}"
        );
        let message = by_name("zzz", dims).unwrap_err().to_string();
        assert!(!message.contains("did you mean"), "{message}");
        assert!(by_name("rm", UVec3::new(1, 4, 4)).is_err());
        assert!(by_name("rm", UVec3::splat(2000)).is_err());
        assert_eq!(
            Dataset::from_name("pbte").unwrap().default_level(),
            PBTE_DEFAULT_LEVEL
        );
    }

    #[test]
    fn bricks_equal_the_same_sub_box_of_the_whole_volume_bit_for_bit() {
        use crate::volume::kd_bricks;
        let dims = UVec3::new(17, 13, 11);
        for dataset in [
            Dataset::RichtmyerMeshkov,
            Dataset::LeadTelluride,
            Dataset::Sphere,
        ] {
            let whole = dataset.generate(dims).unwrap();
            for parts in 1..=5 {
                for brick in kd_bricks(dims - UVec3::ONE, parts) {
                    let part = dataset.generate_brick(dims, &brick).unwrap();
                    let expected = whole.sub_box(brick.samples[0], brick.samples[1]);
                    assert_eq!(part.dims, expected.dims);
                    assert_eq!(part.first, expected.first);
                    assert_eq!(part.spacing, expected.spacing);
                    assert_eq!(part.origin, expected.origin);
                    let bits =
                        |v: &Volume| v.values.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&part), bits(&expected), "{dataset:?} {brick:?}");
                    // Positions and bounds are the whole volume's.
                    let last = part.dims - UVec3::ONE;
                    let global = part.first + last;
                    assert_eq!(
                        part.position(last.x, last.y, last.z),
                        whole.position(global.x, global.y, global.z)
                    );
                }
            }
        }
        let bad = Dataset::Sphere.generate_box(dims, [UVec3::ZERO, dims + UVec3::X]);
        assert!(bad.is_err());
    }
}
