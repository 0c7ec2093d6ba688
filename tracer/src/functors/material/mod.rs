//! `material(id: u32) -> (m: Material)`: material `id` of the scene, as the
//! `shader` functor reads it: `diffuse` (Kd), `shininess` (Ns), `specular`
//! (Ks) and `reflectivity`. An id the scene lacks is an error.
//!
//! With it (and `light`, `colormap`) a pipeline can write its shading model
//! itself instead of calling `shader` (`pipelines/workload2_expressions.dpp`).

use crate::functors::record_fields_mut;
use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(material: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("material")
        .input("id", ElemType::U32)
        .output("m", ElemType::Record(material))
        .doc("material id of the scene: diffuse (Kd), shininess (Ns), specular (Ks), reflectivity");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading = request_resources::<TraceResources>(request, "material")?.shading_gpu_buffers();
    Ok(TwinParts {
        buffers: vec![shading.materials],
        failures: vec!["material: an id names a material the scene does not have".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let materials = ctx.resources::<TraceResources>()?.shading.materials();
    let ids = inputs[0].as_u32();
    if let Some(&id) = ids.iter().find(|&&id| id as usize >= materials.len()) {
        return Err(FunctorError::bad_input(format!(
            "material: id {id}, but the scene has {} materials",
            materials.len()
        )));
    }
    let picked = || ids.iter().map(|&id| &materials[id as usize]);
    let [diffuse, shininess, specular, reflectivity] = record_fields_mut(&mut outputs[0])?;
    *diffuse = Column::Vec3(picked().map(|m| m.kd).collect());
    *shininess = Column::F32(picked().map(|m| m.ns).collect());
    *specular = Column::Vec3(picked().map(|m| m.ks).collect());
    *reflectivity = Column::F32(picked().map(|m| m.reflectivity).collect());
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use dpp_runtime::Column;

    #[test]
    fn the_scene_material_or_an_error() {
        let fixture = Fixture::new();
        let materials = fixture.resources.shading.materials().to_vec();
        let ids = Column::U32(vec![0; 3]);
        let out = fixture.run("material", &[], 0, &[ids.view()]).unwrap();
        let diffuse = out[0].field(0).unwrap();
        assert_eq!(diffuse.view().as_vec3(), &[materials[0].kd; 3]);
        let shininess = out[0].field(1).unwrap();
        assert_eq!(shininess.view().as_f32(), &[materials[0].ns; 3]);
        let past = Column::U32(vec![0, materials.len() as u32]);
        let error = fixture.run("material", &[], 0, &[past.view()]).unwrap_err();
        assert!(error.to_string().contains("material"), "{error}");
    }
}
