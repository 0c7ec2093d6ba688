//! Shading set-up a user can drive: materials, point lights, the colour map and
//! scalar range, the background. [`Shading::for_mesh`] (and
//! [`Shading::for_scene`](crate::TraceScene)) derives defaults from a scene; a [`SceneFile`] (TOML) and command-line overrides change them; the
//! functors read the result from [`crate::TraceResources::shading`].
//!
//! # The shading model (the `shader` functor)
//!
//! All colours are linear RGB; `antiAlias` encodes the final pixel to sRGB. For a
//! hit at `p` with shading normal `n` and view vector `v`:
//!
//! ```text
//! base    = colormap((scalar - min) / (max - min)) * Kd
//! local   = ambient * (1 - occlusion) * base
//!         + sum over visible lights j with n·l > 0 of
//!             att_j * color_j * (base * n·l + Ks * max(n·h, 0)^Ns)    (no Ks term where n·v <= 0)
//! att_j   = intensity_j / (1 + falloff * (d_j / diagonal)^2)
//! rgb     = weight * (1 - reflectivity) * local           (a miss: weight * background)
//! ```
//!
//! with `l` the unit vector to light `j`, `d_j` its distance, `h = normalize(l +
//! v)` and `diagonal` the scene's bounding-box diagonal (so the falloff does not
//! depend on the scene's units). `ambient` and `falloff` are the shader's named
//! parameters. The default lights are placed so that the key light delivers
//! about 1.0 at the scene centre with the default `falloff = 1`.

mod colormap;
mod material;
pub mod paraview;
mod scene_file;
mod series;
mod srgb;

pub use colormap::{ColorMap, COLORMAP_NAMES, COLORMAP_SIZE};
pub use material::{Material, MeshMaterials, DEFAULT_MATERIAL};
pub use scene_file::{ColorSpec, LightSpec, MaterialSpec, SceneFile};
pub use srgb::{encode_in_place as encode_srgb_in_place, linear_to_srgb, srgb_to_linear};

use crate::mesh::Bounds;
use glam::Vec3;
use std::path::PathBuf;
use std::str::FromStr;
use thiserror::Error;

/// `visibleLights` packs one bit per light into a `u32`.
pub const MAX_LIGHTS: usize = 32;

/// The default colour map.
pub const DEFAULT_COLORMAP: &str = "viridis";

/// The default background as a display (sRGB) colour (the same as `normalColor`'s).
pub const DEFAULT_BACKGROUND: Vec3 = Vec3::new(0.1, 0.1, 0.12);

#[derive(Debug, Error)]
pub enum ShadingError {
    #[error("cannot read scene file {}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{origin}: {message}")]
    SceneFile { origin: String, message: String },
    #[error(
        "unknown colour map `{name}`{}; the colour maps are {}",
        suggestion.as_ref().map(|s| format!(" (did you mean `{s}`?)")).unwrap_or_default(),
        COLORMAP_NAMES.join(", ")
    )]
    UnknownColormap {
        name: String,
        suggestion: Option<String>,
    },
    #[error("{0} lights given; at most {MAX_LIGHTS} are supported (visibleLights keeps one bit per light in a u32)")]
    TooManyLights(usize),
    #[error("at least one light is needed (a light of intensity 0 turns lighting off)")]
    NoLights,
    #[error("light {index}: {reason}")]
    BadLight { index: usize, reason: String },
    #[error("bad light `{spec}`: {reason} (expected x,y,z or x,y,z,intensity)")]
    BadLightSpec { spec: String, reason: String },
    #[error("bad scalar range {0}: expected two finite numbers min < max")]
    BadScalarRange(String),
    #[error("background {0:?} must be three finite numbers in [0, 1]")]
    BadBackground([f32; 3]),
    #[error("material `{name}`: {reason}")]
    BadMaterial { name: String, reason: String },
    #[error("the scene has no material `{name}`; its materials are {}", known.join(", "))]
    UnknownMaterial { name: String, known: Vec<String> },
}

/// A point light. `color` is linear RGB (white by default), scaled by `intensity`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    pub position: Vec3,
    pub intensity: f32,
    pub color: Vec3,
}

impl PointLight {
    /// A white light.
    pub fn new(position: Vec3, intensity: f32) -> PointLight {
        PointLight {
            position,
            intensity,
            color: Vec3::ONE,
        }
    }

    fn validate(&self, index: usize) -> Result<(), ShadingError> {
        let bad = |reason: String| ShadingError::BadLight { index, reason };
        if !self.position.is_finite() {
            return Err(bad(format!(
                "position {:?} is not finite",
                self.position.to_array()
            )));
        }
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(bad(format!(
                "intensity {} must be finite and not negative",
                self.intensity
            )));
        }
        if !self.color.is_finite() || self.color.min_element() < 0.0 {
            return Err(bad(format!(
                "colour {:?} must be finite and not negative",
                self.color.to_array()
            )));
        }
        Ok(())
    }
}

impl FromStr for PointLight {
    type Err = ShadingError;

    /// `x,y,z` (intensity 1) or `x,y,z,intensity`, as a command line gives it.
    fn from_str(spec: &str) -> Result<PointLight, ShadingError> {
        let bad = |reason: String| ShadingError::BadLightSpec {
            spec: spec.to_string(),
            reason,
        };
        let numbers = parse_numbers(spec).map_err(bad)?;
        let light = match numbers[..] {
            [x, y, z] => PointLight::new(Vec3::new(x, y, z), 1.0),
            [x, y, z, intensity] => PointLight::new(Vec3::new(x, y, z), intensity),
            _ => return Err(bad(format!("{} numbers", numbers.len()))),
        };
        light.validate(0).map_err(|e| match e {
            ShadingError::BadLight { reason, .. } => bad(reason),
            other => other,
        })?;
        Ok(light)
    }
}

/// `min,max` as a command line gives a scalar range.
pub fn parse_scalar_range(spec: &str) -> Result<[f32; 2], ShadingError> {
    match parse_numbers(spec).as_deref() {
        Ok(&[min, max]) if min.is_finite() && max.is_finite() && min < max => Ok([min, max]),
        _ => Err(ShadingError::BadScalarRange(format!("`{spec}`"))),
    }
}

fn parse_numbers(spec: &str) -> Result<Vec<f32>, String> {
    spec.split(',')
        .map(|part| {
            part.trim()
                .parse::<f32>()
                .map_err(|_| format!("`{}` is not a number", part.trim()))
        })
        .collect()
}

/// What a command line may override (each `None` keeps the current value).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ShadingOverrides {
    pub lights: Option<Vec<PointLight>>,
    pub colormap: Option<String>,
    /// A transfer function (see [`Shading::set_transfer`]), after `colormap`.
    pub transfer: Option<String>,
    pub scalar_range: Option<[f32; 2]>,
    /// Display (sRGB) colour.
    pub background: Option<[f32; 3]>,
}

/// Everything the shading functors read besides the geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct Shading {
    materials: Vec<Material>,
    lights: Vec<PointLight>,
    colormap: ColorMap,
    scalar_range: [f32; 2],
    /// Linear RGB.
    background: Vec3,
}

impl Shading {
    /// The defaults for a mesh of these `bounds` and vertex `scalars`: its
    /// material table (from the MTL, or the default material),
    /// [`default_lights`], `viridis` over the scalar range, and a dark
    /// blue-grey background.
    pub fn for_mesh(materials: &MeshMaterials, bounds: &Bounds, scalars: &[f32]) -> Shading {
        Shading {
            materials: materials.materials.clone(),
            lights: default_lights(bounds),
            colormap: ColorMap::named(DEFAULT_COLORMAP).expect("the default colour map exists"),
            scalar_range: default_scalar_range(scalars),
            background: srgb_to_linear(DEFAULT_BACKGROUND),
        }
    }

    /// Material `id` is entry `id`; 0 is the default material.
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    pub fn lights(&self) -> &[PointLight] {
        &self.lights
    }

    pub fn colormap(&self) -> &ColorMap {
        &self.colormap
    }

    /// The scalar values that map to the colour map's ends (`min < max`).
    pub fn scalar_range(&self) -> [f32; 2] {
        self.scalar_range
    }

    /// Linear RGB.
    pub fn background(&self) -> Vec3 {
        self.background
    }

    /// Replaces the lights: 1 to [`MAX_LIGHTS`] of them, finite, intensities >= 0.
    pub fn set_lights(&mut self, lights: Vec<PointLight>) -> Result<(), ShadingError> {
        if lights.is_empty() {
            return Err(ShadingError::NoLights);
        }
        if lights.len() > MAX_LIGHTS {
            return Err(ShadingError::TooManyLights(lights.len()));
        }
        for (index, light) in lights.iter().enumerate() {
            light.validate(index)?;
        }
        self.lights = lights;
        Ok(())
    }

    pub fn set_colormap(&mut self, name: &str) -> Result<(), ShadingError> {
        self.colormap = ColorMap::named(name)?;
        Ok(())
    }

    /// The colour map and opacity a volume is rendered with: a named colour
    /// map with its opacity ramp, or a ParaView preset file (`FILE.json`, its
    /// first preset, or `FILE.json:NAME`; see [`paraview`]).
    pub fn set_transfer(&mut self, spec: &str) -> Result<(), ShadingError> {
        let lower = spec.to_ascii_lowercase();
        let (path, name) = match lower.rfind(".json") {
            Some(at) if at + 5 == spec.len() => (spec, None),
            Some(at) if spec[at + 5..].starts_with(':') => (&spec[..at + 5], Some(&spec[at + 6..])),
            _ => return self.set_colormap(spec),
        };
        self.colormap = paraview::load_preset(std::path::Path::new(path), name)?;
        Ok(())
    }

    pub fn set_scalar_range(&mut self, min: f32, max: f32) -> Result<(), ShadingError> {
        if !(min.is_finite() && max.is_finite() && min < max) {
            return Err(ShadingError::BadScalarRange(format!("[{min}, {max}]")));
        }
        self.scalar_range = [min, max];
        Ok(())
    }

    /// The colour of rays that miss, as a display (sRGB) colour in [0, 1].
    pub fn set_background(&mut self, srgb: [f32; 3]) -> Result<(), ShadingError> {
        if !srgb.iter().all(|c| (0.0..=1.0).contains(c)) {
            return Err(ShadingError::BadBackground(srgb));
        }
        self.background = srgb_to_linear(Vec3::from(srgb));
        Ok(())
    }

    /// Overrides the given fields of every material called `name`.
    pub fn set_material(&mut self, name: &str, spec: &MaterialSpec) -> Result<(), ShadingError> {
        let mut found = false;
        for material in self.materials.iter_mut().filter(|m| m.name == name) {
            let mut changed = material.clone();
            if let Some(kd) = spec.kd {
                changed.kd = kd.to_vec3();
            }
            if let Some(ks) = spec.ks {
                changed.ks = ks.to_vec3();
            }
            if let Some(ns) = spec.ns {
                changed.ns = ns;
            }
            if let Some(reflectivity) = spec.reflectivity {
                changed.reflectivity = reflectivity;
            }
            changed.validate()?;
            *material = changed;
            found = true;
        }
        if found {
            Ok(())
        } else {
            let mut known: Vec<String> = self.materials.iter().map(|m| m.name.clone()).collect();
            known.dedup();
            Err(ShadingError::UnknownMaterial {
                name: name.to_string(),
                known,
            })
        }
    }

    /// Applies a scene file. All or nothing: on an error, `self` is unchanged.
    pub fn apply(&mut self, file: &SceneFile) -> Result<(), ShadingError> {
        let mut next = self.clone();
        if let Some(lights) = &file.lights {
            next.set_lights(
                lights
                    .iter()
                    .map(|spec| PointLight {
                        position: Vec3::from(spec.position),
                        intensity: spec.intensity,
                        color: spec.color.map_or(Vec3::ONE, ColorSpec::to_vec3),
                    })
                    .collect(),
            )?;
        }
        if let Some(name) = &file.colormap {
            next.set_colormap(name)?;
        }
        if let Some(spec) = &file.transfer {
            next.set_transfer(spec)?;
        }
        if let Some([min, max]) = file.scalar_range {
            next.set_scalar_range(min, max)?;
        }
        if let Some(background) = file.background {
            next.set_background(background)?;
        }
        for (name, spec) in &file.materials {
            next.set_material(name, spec)?;
        }
        *self = next;
        Ok(())
    }

    /// Applies command-line overrides (after any scene file). All or nothing.
    pub fn apply_overrides(&mut self, overrides: &ShadingOverrides) -> Result<(), ShadingError> {
        let mut next = self.clone();
        if let Some(lights) = &overrides.lights {
            next.set_lights(lights.clone())?;
        }
        if let Some(name) = &overrides.colormap {
            next.set_colormap(name)?;
        }
        if let Some(spec) = &overrides.transfer {
            next.set_transfer(spec)?;
        }
        if let Some([min, max]) = overrides.scalar_range {
            next.set_scalar_range(min, max)?;
        }
        if let Some(background) = overrides.background {
            next.set_background(background)?;
        }
        *self = next;
        Ok(())
    }
}

/// A key light above, in front of (+z, where the `front` view looks from) and a
/// little left of the scene, and a dim fill light from the right, both placed
/// relative to the bounding box (centre `c`, diagonal `d`): key at `c + d·(-0.3,
/// 0.6, 0.6)` with intensity 1.81, fill at `c + d·(0.6, 0.15, 0.45)` with
/// intensity 0.5, so that with `falloff = 1` the key delivers 1.0 at `c` and the
/// fill about 0.32.
pub fn default_lights(bounds: &Bounds) -> Vec<PointLight> {
    let (c, d) = (bounds.center(), bounds.diagonal());
    let key = Vec3::new(-0.3, 0.6, 0.6);
    let fill = Vec3::new(0.6, 0.15, 0.45);
    vec![
        PointLight::new(c + d * key, 1.0 + key.length_squared()),
        PointLight::new(c + d * fill, 0.5),
    ]
}

/// The finite scalars' min and max, widened to a unit interval when they are
/// equal; `[0, 1]` without any.
/// The colour map's default range over `scalars`: their finite extremes,
/// widened by 0.5 either way around a single value, [0, 1] without any.
pub fn default_scalar_range(scalars: &[f32]) -> [f32; 2] {
    let (min, max) = scalars
        .iter()
        .filter(|s| s.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &s| {
            (lo.min(s), hi.max(s))
        });
    if min > max {
        [0.0, 1.0]
    } else if min == max {
        [min - 0.5, max + 0.5]
    } else {
        [min, max]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The defaults of a triangle whose scalars are its vertices' y (as
    /// [`crate::TraceScene`] fills them in).
    fn shading() -> Shading {
        let bounds = Bounds {
            min: Vec3::ZERO,
            max: Vec3::new(1.0, 2.0, 0.0),
        };
        Shading::for_mesh(&MeshMaterials::default(), &bounds, &[0.0, 0.0, 2.0])
    }

    /// (The rest of the defaults: `Shading::for_scene`'s test in `scene.rs`.)
    #[test]
    fn default_scalar_ranges_widen_a_single_value_and_skip_nan() {
        assert_eq!(default_scalar_range(&[3.0, 3.0]), [2.5, 3.5]);
        assert_eq!(default_scalar_range(&[f32::NAN]), [0.0, 1.0]);
        assert_eq!(default_scalar_range(&[1.0, f32::NAN, -2.0]), [-2.0, 1.0]);
    }

    #[test]
    fn scene_file_overrides_everything_it_names() {
        let mut shading = shading();
        let file = SceneFile::parse(
            r#"
colormap = "cool-to-warm"
scalar_range = [-1, 1]
background = [1, 1, 1]
lights = [ { position = [1, 2, 3], intensity = 2 } ]
[materials.default]
kd = [1, 0, 0]
reflectivity = 0.25
"#,
            "s.toml",
        )
        .unwrap();
        shading.apply(&file).unwrap();
        assert_eq!(shading.colormap().name(), "cool-to-warm");
        assert_eq!(shading.scalar_range(), [-1.0, 1.0]);
        assert_eq!(shading.background(), Vec3::ONE);
        assert_eq!(
            shading.lights(),
            &[PointLight::new(Vec3::new(1.0, 2.0, 3.0), 2.0)]
        );
        let material = &shading.materials()[0];
        assert_eq!(material.kd, Vec3::X);
        assert_eq!(material.reflectivity, 0.25);
        assert_eq!(material.ns, 32.0);
    }

    #[test]
    fn bad_scene_files_are_errors_and_change_nothing() {
        let original = shading();
        let cases = [
            ("colormap = \"virdis\"", "did you mean `viridis`"),
            ("scalar_range = [2, 1]", "scalar range"),
            ("background = [2, 0, 0]", "background"),
            ("lights = []", "at least one light"),
            (
                "lights = [ { position = [0, 0, 0], intensity = -1 } ]",
                "light 0: intensity -1",
            ),
            (
                "[materials.steel]\nns = 10",
                "no material `steel`; its materials are default",
            ),
            ("[materials.default]\nreflectivity = 2", "[0, 1]"),
            // A valid colour map first, then an error: nothing applies.
            ("colormap = \"grey\"\nscalar_range = [1, 1]", "scalar range"),
        ];
        for (text, expected) in cases {
            let mut shading = original.clone();
            let file = SceneFile::parse(text, "s.toml").unwrap();
            let message = shading.apply(&file).unwrap_err().to_string();
            assert!(message.contains(expected), "{text}: {message}");
            assert_eq!(shading, original, "{text}");
        }
        let many = (0..33)
            .map(|i| format!("{{ position = [{i}, 0, 0] }}"))
            .collect::<Vec<_>>()
            .join(", ");
        let file = SceneFile::parse(&format!("lights = [{many}]"), "s.toml").unwrap();
        let message = original.clone().apply(&file).unwrap_err().to_string();
        assert!(
            message.contains("33 lights") && message.contains("at most 32"),
            "{message}"
        );
    }

    #[test]
    fn command_line_overrides() {
        let mut shading = shading();
        let light: PointLight = "1, 2, 3".parse().unwrap();
        assert_eq!(light, PointLight::new(Vec3::new(1.0, 2.0, 3.0), 1.0));
        let dim: PointLight = "0,0,5,0.5".parse().unwrap();
        assert_eq!(dim.intensity, 0.5);
        for bad in ["1,2", "1,2,x", "1,2,3,4,5", "1,2,3,-1", "nan,0,0"] {
            let message = bad.parse::<PointLight>().unwrap_err().to_string();
            assert!(message.contains(&format!("`{bad}`")), "{message}");
        }
        assert_eq!(parse_scalar_range("-1, 1").unwrap(), [-1.0, 1.0]);
        for bad in ["1", "1,0", "a,b", "0,inf"] {
            assert!(parse_scalar_range(bad).is_err(), "{bad}");
        }
        shading
            .apply_overrides(&ShadingOverrides {
                lights: Some(vec![light, dim]),
                colormap: Some("inferno".into()),
                transfer: None,
                scalar_range: Some([5.0, 6.0]),
                background: None,
            })
            .unwrap();
        assert_eq!(shading.lights(), &[light, dim]);
        assert_eq!(shading.colormap().name(), "inferno");
        assert_eq!(shading.scalar_range(), [5.0, 6.0]);
        let before = shading.clone();
        let error = shading
            .apply_overrides(&ShadingOverrides {
                colormap: Some("plasma".into()),
                lights: Some(vec![light; 40]),
                ..Default::default()
            })
            .unwrap_err();
        assert!(matches!(error, ShadingError::TooManyLights(40)));
        assert_eq!(shading, before);
    }
}
