//! The scene file: a TOML file of shading settings a user writes beside a mesh.
//!
//! ```toml
//! colormap = "cool-to-warm"          # see COLORMAP_NAMES
//! transfer = "preset.json"           # a volume's: a colour map name or a ParaView
//!                                    # preset (relative to this file; FILE.json:NAME)
//! scalar_range = [-1.0, 1.0]         # default: the mesh's scalar min and max
//! background = [0.1, 0.1, 0.12]      # display (sRGB) colour of rays that miss
//! lights = [                          # replaces the default key and fill lights
//!     { position = [0, 3, 2], intensity = 1.5 },
//!     { position = [2, 1, 2], intensity = 0.4, color = [1.0, 0.9, 0.8] },
//! ]
//!
//! [materials.default]                # material 0: triangles without usemtl
//! kd = [0.9, 0.9, 0.9]               # a colour, or one number for grey
//! [materials.steel]                  # overrides the MTL's `steel`, field by field
//! ks = 0.8
//! ns = 200
//! reflectivity = 0.5
//! ```
//!
//! Every key is optional; unknown keys are errors (a typo must not pass silently).

use super::ShadingError;
use glam::Vec3;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub lights: Option<Vec<LightSpec>>,
    pub colormap: Option<String>,
    /// See [`super::Shading::set_transfer`]; a relative preset path is
    /// relative to the scene file's folder once [`SceneFile::load`]ed.
    pub transfer: Option<String>,
    pub scalar_range: Option<[f32; 2]>,
    /// Display (sRGB) colour in [0, 1].
    pub background: Option<[f32; 3]>,
    /// Material overrides by name (see [`super::Material`]).
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    pub position: [f32; 3],
    #[serde(default = "one")]
    pub intensity: f32,
    /// Linear RGB; white when absent.
    pub color: Option<ColorSpec>,
}

fn one() -> f32 {
    1.0
}

/// Fields left out keep the MTL's (or the default) value.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    pub kd: Option<ColorSpec>,
    pub ks: Option<ColorSpec>,
    pub ns: Option<f32>,
    pub reflectivity: Option<f32>,
}

/// A colour as `[r, g, b]` or one number for grey.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(untagged, expecting = "a colour: [r, g, b] or a single number")]
pub enum ColorSpec {
    Grey(f32),
    Rgb([f32; 3]),
}

impl ColorSpec {
    pub fn to_vec3(self) -> Vec3 {
        match self {
            ColorSpec::Grey(value) => Vec3::splat(value),
            ColorSpec::Rgb(rgb) => Vec3::from(rgb),
        }
    }
}

impl SceneFile {
    /// Reads and parses a scene file. Errors name the file; TOML errors give the
    /// line and column.
    pub fn load(path: &Path) -> Result<SceneFile, ShadingError> {
        let text = std::fs::read_to_string(path).map_err(|source| ShadingError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut file = SceneFile::parse(&text, &path.display().to_string())?;
        if let (Some(transfer), Some(folder)) = (&mut file.transfer, path.parent()) {
            let is_file = transfer.to_ascii_lowercase().contains(".json");
            if is_file && Path::new(transfer.as_str()).is_relative() {
                *transfer = folder.join(&*transfer).to_string_lossy().into_owned();
            }
        }
        Ok(file)
    }

    /// Parses scene-file text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<SceneFile, ShadingError> {
        let file: SceneFile = toml::from_str(text).map_err(|error| ShadingError::SceneFile {
            origin: origin.to_string(),
            message: error.to_string().trim_end().to_string(),
        })?;
        file.check_finite()
            .map_err(|message| ShadingError::SceneFile {
                origin: origin.to_string(),
                message,
            })?;
        Ok(file)
    }

    /// Every number finite (TOML allows `nan` and `inf`); ranges are checked
    /// where the values are applied.
    fn check_finite(&self) -> Result<(), String> {
        let finite = |what: String, values: &[f32]| {
            if values.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err(format!("{what} = {values:?} is not finite"))
            }
        };
        for (i, light) in self.lights.iter().flatten().enumerate() {
            finite(format!("lights[{i}].position"), &light.position)?;
            finite(format!("lights[{i}].intensity"), &[light.intensity])?;
            if let Some(color) = light.color {
                finite(format!("lights[{i}].color"), &color.to_vec3().to_array())?;
            }
        }
        if let Some(range) = self.scalar_range {
            finite("scalar_range".into(), &range)?;
        }
        if let Some(background) = self.background {
            finite("background".into(), &background)?;
        }
        for (name, spec) in &self.materials {
            for (key, color) in [("kd", spec.kd), ("ks", spec.ks)] {
                if let Some(color) = color {
                    finite(
                        format!("materials.{name}.{key}"),
                        &color.to_vec3().to_array(),
                    )?;
                }
            }
            for (key, value) in [("ns", spec.ns), ("reflectivity", spec.reflectivity)] {
                if let Some(value) = value {
                    finite(format!("materials.{name}.{key}"), &[value])?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_file_parses() {
        let text = r#"
colormap = "inferno"
scalar_range = [-1, 2.5]
background = [0, 0, 0]
lights = [
    { position = [0, 3, 2], intensity = 1.5 },
    { position = [2.0, 1.0, 2.0], color = [1.0, 0.5, 0.25] },
]
[materials.default]
kd = 0.5
[materials.steel]
ks = [0.8, 0.8, 0.9]
ns = 200
reflectivity = 0.5
"#;
        let file = SceneFile::parse(text, "scene.toml").unwrap();
        assert_eq!(file.colormap.as_deref(), Some("inferno"));
        assert_eq!(file.scalar_range, Some([-1.0, 2.5]));
        assert_eq!(file.background, Some([0.0; 3]));
        let lights = file.lights.unwrap();
        assert_eq!(lights.len(), 2);
        assert_eq!(lights[0].position, [0.0, 3.0, 2.0]);
        assert_eq!(lights[0].intensity, 1.5);
        assert_eq!(lights[0].color, None);
        assert_eq!(lights[1].intensity, 1.0);
        assert_eq!(
            lights[1].color.unwrap().to_vec3(),
            Vec3::new(1.0, 0.5, 0.25)
        );
        assert_eq!(
            file.materials["default"].kd.unwrap().to_vec3(),
            Vec3::splat(0.5)
        );
        let steel = &file.materials["steel"];
        assert_eq!(steel.ns, Some(200.0));
        assert_eq!(steel.reflectivity, Some(0.5));
        assert_eq!(steel.kd, None);
        assert_eq!(SceneFile::parse("", "empty").unwrap(), SceneFile::default());
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let error = SceneFile::parse(
            "colormap = \"viridis\"\nlights = [ { position = [1, 2] } ]\n",
            "a.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(error.starts_with("a.toml:"), "{error}");
        assert!(error.contains("line 2"), "{error}");

        let error = SceneFile::parse("colourmap = \"viridis\"\n", "b.toml")
            .unwrap_err()
            .to_string();
        assert!(error.contains("unknown field `colourmap`"), "{error}");
        assert!(error.contains("line 1"), "{error}");

        let error = SceneFile::parse("colormap = viridis\n", "c.toml")
            .unwrap_err()
            .to_string();
        assert!(error.contains("line 1"), "{error}");

        let error = SceneFile::parse("[materials.x]\nkd = \"red\"\n", "d.toml")
            .unwrap_err()
            .to_string();
        assert!(error.contains("a colour"), "{error}");
        assert!(error.contains("line 2"), "{error}");
    }

    #[test]
    fn non_finite_numbers_are_errors() {
        for (text, what) in [
            (
                "lights = [ { position = [nan, 0, 0] } ]",
                "lights[0].position",
            ),
            (
                "lights = [ { position = [0, 0, 0], intensity = inf } ]",
                "lights[0].intensity",
            ),
            ("scalar_range = [0, inf]", "scalar_range"),
            ("background = [0, -nan, 0]", "background"),
            ("[materials.m]\nns = nan", "materials.m.ns"),
            ("[materials.m]\nkd = inf", "materials.m.kd"),
        ] {
            let error = SceneFile::parse(text, "f.toml").unwrap_err().to_string();
            assert!(
                error.contains(what) && error.contains("not finite"),
                "{error}"
            );
        }
    }

    #[test]
    fn load_reads_a_file_and_reports_a_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(&path, "colormap = \"grey\"\n").unwrap();
        assert_eq!(
            SceneFile::load(&path).unwrap().colormap.as_deref(),
            Some("grey")
        );
        let missing = dir.path().join("missing.toml");
        let error = SceneFile::load(&missing).unwrap_err().to_string();
        assert!(error.contains("missing.toml"), "{error}");
    }
}
