//! Blinn–Phong materials, from an OBJ's MTL file or the defaults.

use super::ShadingError;
use glam::Vec3;

/// Name of material 0, which every triangle without a (known) `usemtl` uses.
pub const DEFAULT_MATERIAL: &str = "default";

/// A Blinn–Phong material. Colours are linear RGB factors in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse factor: multiplies the colour map's colour.
    pub kd: Vec3,
    /// Specular colour.
    pub ks: Vec3,
    /// Blinn–Phong exponent (shininess), >= 0.
    pub ns: f32,
    /// Fraction of light that the mirror reflection carries, in [0, 1]: the local
    /// colour is scaled by `1 - reflectivity`, the reflection ray's weight by
    /// `reflectivity`.
    pub reflectivity: f32,
}

impl Material {
    /// The defaults: `Kd` white, `Ks` 0.3, `Ns` 32, no reflection.
    pub fn named(name: &str) -> Material {
        Material {
            name: name.to_string(),
            kd: Vec3::ONE,
            ks: Vec3::splat(0.3),
            ns: 32.0,
            reflectivity: 0.0,
        }
    }

    /// A material from an MTL entry: `Kd`, `Ks` and `Ns` where given (defaults
    /// otherwise); the reflectivity is, in order of precedence, the unofficial
    /// `refl` parameter, the PBR extension's metallic `Pm`, or for the mirror
    /// illumination models `illum 3` and `illum 5` the mean of `Ks`; else 0.
    pub fn from_mtl(mtl: &tobj::Material) -> Result<Material, ShadingError> {
        let mut material = Material::named(&mtl.name);
        if let Some(kd) = mtl.diffuse {
            material.kd = Vec3::from(kd);
        }
        if let Some(ks) = mtl.specular {
            material.ks = Vec3::from(ks);
        }
        if let Some(ns) = mtl.shininess {
            material.ns = ns;
        }
        let parameter = |key: &str| -> Result<Option<f32>, ShadingError> {
            mtl.unknown_param
                .get(key)
                .map(|text| {
                    text.trim()
                        .parse::<f32>()
                        .map_err(|_| ShadingError::BadMaterial {
                            name: mtl.name.clone(),
                            reason: format!("`{key} {text}` is not a number"),
                        })
                })
                .transpose()
        };
        material.reflectivity = match (parameter("refl")?, parameter("Pm")?) {
            (Some(refl), _) => refl,
            (None, Some(metallic)) => metallic,
            (None, None) if matches!(mtl.illumination_model, Some(3 | 5)) => {
                material.ks.element_sum() / 3.0
            }
            (None, None) => 0.0,
        };
        material.validate()?;
        Ok(material)
    }

    /// Finite colours and exponent, `Ns >= 0`, reflectivity in [0, 1].
    pub fn validate(&self) -> Result<(), ShadingError> {
        let bad = |reason: String| ShadingError::BadMaterial {
            name: self.name.clone(),
            reason,
        };
        for (what, color) in [("Kd", self.kd), ("Ks", self.ks)] {
            if !color.is_finite() || color.min_element() < 0.0 {
                return Err(bad(format!(
                    "{what} {:?} must be finite and not negative",
                    color.to_array()
                )));
            }
        }
        if !(self.ns.is_finite() && self.ns >= 0.0) {
            return Err(bad(format!(
                "Ns {} must be finite and not negative",
                self.ns
            )));
        }
        if !(0.0..=1.0).contains(&self.reflectivity) {
            return Err(bad(format!(
                "reflectivity {} must lie in [0, 1]",
                self.reflectivity
            )));
        }
        Ok(())
    }
}

/// A scene's material table and each triangle's entry in it.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshMaterials {
    /// Entry 0 is [`DEFAULT_MATERIAL`]; the MTL's materials follow in file order.
    pub materials: Vec<Material>,
    /// The material id of each triangle (input order), or empty when every
    /// triangle uses material 0.
    pub triangle_materials: Vec<u32>,
}

impl Default for MeshMaterials {
    /// The default material for every triangle.
    fn default() -> MeshMaterials {
        MeshMaterials {
            materials: vec![Material::named(DEFAULT_MATERIAL)],
            triangle_materials: Vec::new(),
        }
    }
}

impl MeshMaterials {
    /// The material id of triangle `prim` (0 for an unknown triangle).
    #[inline]
    pub fn triangle_material(&self, prim: u32) -> u32 {
        self.triangle_materials
            .get(prim as usize)
            .copied()
            .unwrap_or(0)
    }

    /// Checks the table against a mesh of `triangles` triangles.
    pub fn validate(&self, triangles: usize) -> Result<(), String> {
        if self.materials.is_empty() {
            return Err("the material table is empty (material 0 must exist)".into());
        }
        if !self.triangle_materials.is_empty() && self.triangle_materials.len() != triangles {
            return Err(format!(
                "{} per-triangle material ids for {triangles} triangles",
                self.triangle_materials.len()
            ));
        }
        if let Some((triangle, id)) = self
            .triangle_materials
            .iter()
            .enumerate()
            .find(|(_, &id)| id as usize >= self.materials.len())
        {
            return Err(format!(
                "triangle {triangle} uses material {id}, but there are only {}",
                self.materials.len()
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mtl(name: &str) -> tobj::Material {
        tobj::Material {
            name: name.into(),
            ..Default::default()
        }
    }

    #[test]
    fn defaults_and_mtl_values() {
        let plain = Material::from_mtl(&mtl("plain")).unwrap();
        assert_eq!(plain, Material::named("plain"));
        let mut shiny = mtl("shiny");
        shiny.diffuse = Some([0.5, 0.25, 1.0]);
        shiny.specular = Some([0.9, 0.6, 0.3]);
        shiny.shininess = Some(100.0);
        shiny.illumination_model = Some(3);
        let material = Material::from_mtl(&shiny).unwrap();
        assert_eq!(material.kd, Vec3::new(0.5, 0.25, 1.0));
        assert_eq!(material.ns, 100.0);
        assert!((material.reflectivity - 0.6).abs() < 1e-6);
        shiny.unknown_param.insert("Pm".into(), "0.25".into());
        assert_eq!(Material::from_mtl(&shiny).unwrap().reflectivity, 0.25);
        shiny.unknown_param.insert("refl".into(), " 0.75".into());
        assert_eq!(Material::from_mtl(&shiny).unwrap().reflectivity, 0.75);
        shiny.illumination_model = Some(2);
        shiny.unknown_param.clear();
        assert_eq!(Material::from_mtl(&shiny).unwrap().reflectivity, 0.0);
    }

    #[test]
    fn bad_values_are_errors() {
        let mut bad = mtl("bad");
        bad.unknown_param.insert("refl".into(), "lots".into());
        let message = Material::from_mtl(&bad).unwrap_err().to_string();
        assert!(
            message.contains("`bad`") && message.contains("refl lots"),
            "{message}"
        );
        bad.unknown_param.insert("refl".into(), "1.5".into());
        let message = Material::from_mtl(&bad).unwrap_err().to_string();
        assert!(message.contains("[0, 1]"), "{message}");
        let mut negative = mtl("negative");
        negative.shininess = Some(-1.0);
        assert!(Material::from_mtl(&negative).is_err());
        negative.shininess = Some(f32::NAN);
        assert!(Material::from_mtl(&negative).is_err());
    }

    #[test]
    fn table_validation() {
        let mut table = MeshMaterials::default();
        assert_eq!(table.validate(5), Ok(()));
        table.triangle_materials = vec![0, 0, 1];
        assert!(table.validate(3).unwrap_err().contains("material 1"));
        table.triangle_materials = vec![0, 0];
        assert!(table.validate(3).unwrap_err().contains("2 per-triangle"));
    }
}
