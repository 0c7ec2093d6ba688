//! ParaView's colour-map presets ("Export preset" in its colour-map editor):
//! a JSON list of objects (or one object) with `Name`, `ColorSpace`,
//! `RGBPoints` (`x, r, g, b, …`, colours in [0, 1]) and optionally `Points`
//! (`x, opacity, midpoint, sharpness, …`), read into a [`ColorMap`]: a
//! volume's transfer function.
//!
//! As ParaView does when a preset is applied, the points' `x` are rescaled from
//! the `RGBPoints` range onto the scalar range in use (the data's, or
//! `--scalar-range`); `Points` are read on the same scale. Between points colours
//! blend in the preset's `ColorSpace`: `RGB` linearly, `Lab` (or `CIELAB`) in
//! CIE L*a*b*, and `Diverging` in L*a*b* too (an approximation of Moreland's Msh
//! interpolation, as for the `cool-to-warm` map); `HSV` is refused. Opacity is
//! piecewise linear between `Points`; their midpoint and sharpness (ParaView's
//! curve shaping, 0.5 and 0 for linear) are read but not applied. Without
//! `Points`, opacity ramps from 0 to 1 as for the named maps.

use super::{ColorMap, ShadingError, COLORMAP_SIZE};
use colorgrad::{BlendMode, Color, GradientBuilder, LinearGradient};
use serde::Deserialize;
use std::path::Path;

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum Presets {
    List(Vec<Preset>),
    One(Preset),
}

#[derive(Debug, Deserialize)]
struct Preset {
    #[serde(rename = "Name")]
    name: Option<String>,
    #[serde(rename = "ColorSpace")]
    color_space: Option<String>,
    #[serde(rename = "RGBPoints")]
    rgb_points: Option<Vec<f64>>,
    #[serde(rename = "Points")]
    points: Option<Vec<f64>>,
}

/// The preset of `path` called `name` (`None`: the first preset with
/// `RGBPoints`). Errors name the file and say what is wrong.
pub fn load_preset(path: &Path, name: Option<&str>) -> Result<ColorMap, ShadingError> {
    let failed = |message: String| ShadingError::SceneFile {
        origin: path.display().to_string(),
        message,
    };
    let text = std::fs::read_to_string(path)
        .map_err(|e| failed(format!("cannot read the colour-map preset: {e}")))?;
    parse_preset(&text, name).map_err(failed)
}

/// [`load_preset`] of JSON text.
pub fn parse_preset(text: &str, name: Option<&str>) -> Result<ColorMap, String> {
    let presets = match serde_json::from_str::<Presets>(text) {
        Ok(Presets::List(list)) => list,
        Ok(Presets::One(one)) => vec![one],
        Err(e) => return Err(format!("not a ParaView colour-map preset (JSON): {e}")),
    };
    let names = || {
        let names: Vec<&str> = presets.iter().filter_map(|p| p.name.as_deref()).collect();
        names.join(", ")
    };
    let preset = match name {
        Some(name) => presets
            .iter()
            .find(|p| p.name.as_deref() == Some(name))
            .ok_or_else(|| format!("no preset named `{name}` (the file has {})", names()))?,
        None => presets
            .iter()
            .find(|p| p.rgb_points.is_some())
            .ok_or("no preset with RGBPoints")?,
    };
    let label = preset.name.clone().unwrap_or_else(|| "preset".into());
    let bad = |message: String| format!("preset `{label}`: {message}");
    let rgb = preset
        .rgb_points
        .as_deref()
        .ok_or_else(|| bad("it has no RGBPoints".into()))?;
    if rgb.len() < 8 || rgb.len() % 4 != 0 || rgb.iter().any(|v| !v.is_finite()) {
        return Err(bad(format!(
            "RGBPoints must be at least two groups of 4 finite numbers (x, r, g, b), got {} numbers",
            rgb.len()
        )));
    }
    let rgb: Vec<&[f64]> = rgb.chunks(4).collect();
    let (lo, hi) = (rgb[0][0], rgb[rgb.len() - 1][0]);
    if rgb.windows(2).any(|w| w[1][0] < w[0][0]) || lo >= hi {
        return Err(bad(
            "the x of RGBPoints must increase, first below last".into()
        ));
    }
    if rgb
        .iter()
        .any(|p| p[1..].iter().any(|c| !(0.0..=1.0).contains(c)))
    {
        return Err(bad("RGBPoints colours must be in [0, 1]".into()));
    }
    let unit = |x: f64| ((x - lo) / (hi - lo)) as f32;
    let mode = match preset.color_space.as_deref().unwrap_or("RGB") {
        "RGB" => BlendMode::Rgb,
        "Lab" | "CIELAB" | "Diverging" => BlendMode::Lab,
        other => {
            return Err(bad(format!(
                "ColorSpace `{other}` is not supported (RGB, Lab, CIELAB, Diverging are)"
            )))
        }
    };
    let colors: Vec<Color> = (rgb.iter())
        .map(|p| Color::new(p[1] as f32, p[2] as f32, p[3] as f32, 1.0))
        .collect();
    let positions: Vec<f32> = rgb.iter().map(|p| unit(p[0])).collect();
    let gradient = GradientBuilder::new()
        .colors(&colors)
        .domain(&positions)
        .mode(mode)
        .build::<LinearGradient>()
        .map_err(|e| bad(format!("its colours make no gradient: {e}")))?;
    let at = |i: usize| i as f32 / (COLORMAP_SIZE - 1) as f32;
    let opacity = match preset.points.as_deref() {
        None => (0..COLORMAP_SIZE).map(at).collect(),
        Some(points) => {
            if points.len() < 4 || points.len() % 4 != 0 || points.iter().any(|v| !v.is_finite()) {
                return Err(bad(format!(
                    "Points must be groups of 4 finite numbers (x, opacity, midpoint, sharpness), got {} numbers",
                    points.len()
                )));
            }
            let points: Vec<(f32, f32)> = (points.chunks(4))
                .map(|p| (unit(p[0]), p[1] as f32))
                .collect();
            if points.windows(2).any(|w| w[1].0 < w[0].0) {
                return Err(bad("the x of Points must not decrease".into()));
            }
            if points.iter().any(|p| !(0.0..=1.0).contains(&p.1)) {
                return Err(bad("opacities in Points must be in [0, 1]".into()));
            }
            (0..COLORMAP_SIZE)
                .map(|i| piecewise_linear(&points, at(i)))
                .collect()
        }
    };
    Ok(ColorMap::sampled(label, &gradient, opacity))
}

/// The piecewise-linear function through `points` (sorted by x) at `x`,
/// constant beyond the first and last point.
fn piecewise_linear(points: &[(f32, f32)], x: f32) -> f32 {
    let (first, last) = (points[0], points[points.len() - 1]);
    if x <= first.0 {
        return first.1;
    }
    if x >= last.0 {
        return last.1;
    }
    let next = points
        .iter()
        .position(|p| p.0 > x)
        .unwrap_or(points.len() - 1);
    let (a, b) = (points[next - 1], points[next]);
    a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// As ParaView 5.11 exports its "Cool to Warm" and a custom preset.
    const PRESETS: &str = r#"[
        {
            "ColorSpace" : "Diverging",
            "Name" : "Cool to Warm",
            "NanColor" : [ 1, 1, 0 ],
            "RGBPoints" : [ 0, 0.23, 0.299, 0.754, 0.5, 0.865, 0.865, 0.865, 1, 0.706, 0.016, 0.15 ]
        },
        {
            "ColorSpace" : "RGB",
            "Name" : "ramp",
            "Points" : [ -10, 0, 0.5, 0, 0, 0, 0.5, 0, 10, 0.8, 0.5, 0 ],
            "RGBPoints" : [ -10, 0, 0, 0, 10, 1, 1, 1 ]
        }
    ]"#;

    #[test]
    fn presets_are_found_by_name_and_rescaled_to_the_unit_range() {
        let first = parse_preset(PRESETS, None).unwrap();
        assert_eq!(first.name(), "Cool to Warm");
        assert!(
            (first.srgb()[0] - Vec3::new(0.23, 0.299, 0.754))
                .abs()
                .max_element()
                < 1e-6
        );
        let ramp = parse_preset(PRESETS, Some("ramp")).unwrap();
        // RGB blends linearly: grey 0.5 at the middle.
        assert!((ramp.srgb_at(0.5) - Vec3::splat(0.5)).abs().max_element() < 1e-3);
        // Opacity 0 up to x = 0 (the middle), then 0.8 at x = 10.
        assert_eq!(ramp.opacity()[0], 0.0);
        assert_eq!(ramp.opacity()[127], 0.0);
        assert!((ramp.opacity()[255] - 0.8).abs() < 1e-6);
        assert!((ramp.rgba_at(0.75).1 - 0.4).abs() < 1e-2);
        assert!(ramp.transparent_between(0.0, 0.49));
        assert!(!ramp.transparent_between(0.0, 0.6));
        // Without Points: the ramp of the named maps.
        assert_eq!(first.opacity()[255], 1.0);
    }

    #[test]
    fn bad_presets_say_what_is_wrong() {
        for (text, expected) in [
            ("{", "not a ParaView colour-map preset"),
            (r#"[{"Name": "a"}]"#, "no preset with RGBPoints"),
            (
                r#"{"Name": "a", "RGBPoints": [0, 0, 0, 0]}"#,
                "at least two groups",
            ),
            (
                r#"{"RGBPoints": [1, 0, 0, 0, 0, 1, 1, 1]}"#,
                "must increase",
            ),
            (r#"{"RGBPoints": [0, 0, 0, 2, 1, 1, 1, 1]}"#, "in [0, 1]"),
            (
                r#"{"ColorSpace": "HSV", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1]}"#,
                "HSV",
            ),
            (
                r#"{"RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1], "Points": [0, 2, 0.5, 0]}"#,
                "opacities",
            ),
        ] {
            let error = parse_preset(text, None).unwrap_err();
            assert!(error.contains(expected), "{text}: {error}");
        }
        let error = parse_preset(PRESETS, Some("nope")).unwrap_err();
        assert!(error.contains("Cool to Warm, ramp"), "{error}");
    }
}
