//! Colour maps for per-vertex scalars, from the `colorgrad` crate, sampled into a
//! 256-entry lookup table at set-up.
//!
//! - `viridis`, `inferno`, `magma`, `plasma`: colorgrad's ports of d3's (and
//!   matplotlib's) perceptually uniform maps; `cividis` and `turbo` likewise;
//! - `cool-to-warm`: ParaView's default diverging map (K. Moreland, "Diverging
//!   Color Maps for Scientific Visualization", 2009): Moreland's endpoint colours
//!   (59, 76, 192) and (180, 4, 38) through his near-white midpoint (221, 221,
//!   221), blended by colorgrad's gradient builder in CIE L*a*b* (an approximation
//!   of Moreland's Msh interpolation, which colorgrad does not offer);
//! - `grey` (or `gray`): black to white, blended in sRGB.
//!
//! Gradient colours are display (sRGB-encoded) values. The shader works in linear
//! RGB and `antiAlias` encodes the final pixel to sRGB, so the table keeps both:
//! [`ColorMap::srgb`] as the crate gives it, [`ColorMap::linear`] decoded.
//!
//! A colour map is also a volume's transfer function: beside the colours it
//! keeps an opacity table on the same 256 points ([`ColorMap::opacity`]), a
//! ramp from 0 to 1 for the named maps, or a ParaView preset's own opacity
//! points ([`super::paraview`]).

use super::{srgb_to_linear, ShadingError};
use colorgrad::{BlendMode, Color, Gradient, GradientBuilder, LinearGradient};
use glam::Vec3;

/// Entries of a colour map's lookup table.
pub const COLORMAP_SIZE: usize = 256;

/// Every colour map name [`ColorMap::named`] accepts (besides the alias `gray`).
pub const COLORMAP_NAMES: [&str; 8] = [
    "viridis",
    "inferno",
    "magma",
    "plasma",
    "cividis",
    "turbo",
    "cool-to-warm",
    "grey",
];

/// A colour map sampled at `i / 255` for `i` in `0..256`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColorMap {
    name: String,
    // Arrays of the table's size, so that a lookup needs no bounds check.
    srgb: [Vec3; COLORMAP_SIZE],
    linear: [Vec3; COLORMAP_SIZE],
    opacity: Vec<f32>,
}

impl ColorMap {
    /// The colour map called `name` (one of [`COLORMAP_NAMES`], case-insensitive).
    pub fn named(name: &str) -> Result<ColorMap, ShadingError> {
        let key = name.trim().to_ascii_lowercase();
        let gradient: Box<dyn Gradient> = match key.as_str() {
            "viridis" => Box::new(colorgrad::preset::viridis()),
            "inferno" => Box::new(colorgrad::preset::inferno()),
            "magma" => Box::new(colorgrad::preset::magma()),
            "plasma" => Box::new(colorgrad::preset::plasma()),
            "cividis" => Box::new(colorgrad::preset::cividis()),
            "turbo" => Box::new(colorgrad::preset::turbo()),
            "cool-to-warm" => Box::new(cool_to_warm()),
            "grey" | "gray" => Box::new(grey()),
            _ => return Err(unknown_colormap(name)),
        };
        let canonical = if key == "gray" {
            "grey".to_string()
        } else {
            key
        };
        let ramp = (0..COLORMAP_SIZE).map(|i| i as f32 / (COLORMAP_SIZE - 1) as f32);
        Ok(ColorMap::sampled(
            canonical,
            gradient.as_ref(),
            ramp.collect(),
        ))
    }

    /// `gradient` sampled at the table's points, with `opacity` (one per point).
    pub(crate) fn sampled(name: String, gradient: &dyn Gradient, opacity: Vec<f32>) -> ColorMap {
        let srgb: [Vec3; COLORMAP_SIZE] = std::array::from_fn(|i| {
            let color = gradient.at(i as f32 / (COLORMAP_SIZE - 1) as f32);
            Vec3::new(color.r, color.g, color.b).clamp(Vec3::ZERO, Vec3::ONE)
        });
        let linear = srgb.map(srgb_to_linear);
        ColorMap {
            name,
            srgb,
            linear,
            opacity,
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The table as display (sRGB) colours.
    pub fn srgb(&self) -> &[Vec3] {
        &self.srgb
    }

    /// The table in linear RGB, which the shader reads.
    pub fn linear(&self) -> &[Vec3] {
        &self.linear
    }

    /// The linear colour at `t` in [0, 1] (clamped; NaN reads as 0), interpolated
    /// linearly between table entries.
    #[inline]
    pub fn linear_at(&self, t: f32) -> Vec3 {
        lerp_table(&self.linear, t)
    }

    /// The display colour at `t`, as [`ColorMap::linear_at`] does it.
    pub fn srgb_at(&self, t: f32) -> Vec3 {
        lerp_table(&self.srgb, t)
    }

    /// The opacity table (in [0, 1]) on the colours' points: what a volume's
    /// transfer function gives per unit distance (one cell).
    pub fn opacity(&self) -> &[f32] {
        &self.opacity
    }

    /// The linear colour and opacity at `t`, each interpolated as
    /// [`ColorMap::linear_at`] does.
    #[inline]
    pub fn rgba_at(&self, t: f32) -> (Vec3, f32) {
        let (low, frac) = table_point(t);
        let (o0, o1) = (self.opacity[low], self.opacity[low + 1]);
        (
            self.linear[low].lerp(self.linear[low + 1], frac),
            o0 + (o1 - o0) * frac,
        )
    }

    /// Whether the opacity is 0 wherever `t` in `[lo, hi]` reads the table
    /// (the entries around both ends included): a span of values the volume
    /// renderer may skip.
    pub fn transparent_between(&self, lo: f32, hi: f32) -> bool {
        let (first, _) = table_point(lo);
        let (last, _) = table_point(hi);
        self.opacity[first..=last + 1].iter().all(|&a| a == 0.0)
    }
}

/// The entry below `t` (clamped to [0, 1]; NaN reads as 0) and the fraction
/// of the way to the next one.
#[inline]
fn table_point(t: f32) -> (usize, f32) {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (COLORMAP_SIZE - 1) as f32;
    // `x` is in [0, 255]: as u32 it converts as `as usize` did, and the
    // bound below lets a lookup in a table of 256 skip its bounds checks.
    let low = (x as u32).min(COLORMAP_SIZE as u32 - 2);
    (low as usize, x - low as f32)
}

#[inline]
fn lerp_table(table: &[Vec3; COLORMAP_SIZE], t: f32) -> Vec3 {
    let (low, frac) = table_point(t);
    table[low].lerp(table[low + 1], frac)
}

fn unknown_colormap(name: &str) -> ShadingError {
    let suggestion = COLORMAP_NAMES
        .iter()
        .map(|known| {
            (
                strsim::jaro_winkler(&name.to_ascii_lowercase(), known),
                *known,
            )
        })
        .filter(|(score, _)| *score > 0.7)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, known)| known.to_string());
    ShadingError::UnknownColormap {
        name: name.to_string(),
        suggestion,
    }
}

fn build(colors: &[Color], mode: BlendMode) -> LinearGradient {
    GradientBuilder::new()
        .colors(colors)
        .mode(mode)
        .build::<LinearGradient>()
        // Two or three finite colours and no positions: the builder cannot fail.
        .expect("a gradient of fixed valid colours")
}

/// Moreland's cool-to-warm map: his endpoints through his midpoint, in L*a*b*.
fn cool_to_warm() -> LinearGradient {
    build(
        &[
            Color::from_rgba8(59, 76, 192, 255),
            Color::from_rgba8(221, 221, 221, 255),
            Color::from_rgba8(180, 4, 38, 255),
        ],
        BlendMode::Lab,
    )
}

fn grey() -> LinearGradient {
    build(
        &[
            Color::from_rgba8(0, 0, 0, 255),
            Color::from_rgba8(255, 255, 255, 255),
        ],
        BlendMode::Rgb,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn crate_value(gradient: &dyn Gradient, t: f32) -> Vec3 {
        let c = gradient.at(t);
        Vec3::new(c.r, c.g, c.b)
    }

    fn close(a: Vec3, b: Vec3, tolerance: f32) -> bool {
        (a - b).abs().max_element() <= tolerance
    }

    #[test]
    fn required_maps_match_the_crate_at_0_half_and_1() {
        let cases: [(&str, Box<dyn Gradient>); 3] = [
            ("viridis", Box::new(colorgrad::preset::viridis())),
            ("inferno", Box::new(colorgrad::preset::inferno())),
            ("cool-to-warm", Box::new(cool_to_warm())),
        ];
        for (name, gradient) in cases {
            let map = ColorMap::named(name).unwrap();
            assert_eq!(map.name(), name);
            assert_eq!(map.srgb().len(), COLORMAP_SIZE);
            assert_eq!(map.srgb()[0], crate_value(gradient.as_ref(), 0.0), "{name}");
            assert_eq!(
                map.srgb()[255],
                crate_value(gradient.as_ref(), 1.0),
                "{name}"
            );
            // 0.5 falls between entries 127 and 128: interpolation stays within
            // what half a table step can change.
            assert!(
                close(map.srgb_at(0.5), crate_value(gradient.as_ref(), 0.5), 0.01),
                "{name}: {} vs {}",
                map.srgb_at(0.5),
                crate_value(gradient.as_ref(), 0.5)
            );
        }
        // The known end colours of viridis and inferno (d3's tables).
        let viridis = ColorMap::named("viridis").unwrap();
        assert!(close(
            viridis.srgb()[0],
            Vec3::new(68.0, 1.0, 84.0) / 255.0,
            1e-3
        ));
        let inferno = ColorMap::named("inferno").unwrap();
        assert!(close(
            inferno.srgb()[0],
            Vec3::new(0.0, 0.0, 4.0) / 255.0,
            1e-3
        ));
    }

    #[test]
    fn cool_to_warm_has_morelands_endpoints_and_grey_middle() {
        let map = ColorMap::named("Cool-To-Warm").unwrap();
        assert!(close(
            map.srgb_at(0.0),
            Vec3::new(59.0, 76.0, 192.0) / 255.0,
            1e-3
        ));
        assert!(close(
            map.srgb_at(1.0),
            Vec3::new(180.0, 4.0, 38.0) / 255.0,
            1e-3
        ));
        assert!(close(map.srgb_at(0.5), Vec3::splat(221.0 / 255.0), 0.01));
    }

    #[test]
    fn grey_is_black_to_white_and_linear_is_decoded() {
        let map = ColorMap::named("gray").unwrap();
        assert_eq!(map.name(), "grey");
        assert_eq!(map.srgb_at(0.0), Vec3::ZERO);
        assert_eq!(map.srgb_at(1.0), Vec3::ONE);
        assert!(close(map.srgb_at(0.5), Vec3::splat(0.5), 1e-3));
        // sRGB 0.5 is about 0.214 in linear light.
        assert!(close(map.linear_at(0.5), Vec3::splat(0.214), 2e-3));
        assert_eq!(map.linear_at(f32::NAN), Vec3::ZERO);
        assert_eq!(map.linear_at(7.0), Vec3::ONE);
    }

    #[test]
    fn unknown_name_suggests_a_close_one() {
        let error = ColorMap::named("vridis").unwrap_err();
        let message = error.to_string();
        assert!(message.contains("`vridis`"), "{message}");
        assert!(message.contains("did you mean `viridis`"), "{message}");
        assert!(message.contains("cool-to-warm"), "{message}");
        let message = ColorMap::named("zzz").unwrap_err().to_string();
        assert!(!message.contains("did you mean"), "{message}");
        for name in COLORMAP_NAMES {
            assert_eq!(ColorMap::named(name).unwrap().name(), name);
        }
    }
}
