//! `cameraRay(index: u32) -> (ray: Ray) [spp: int = 1]`: primary rays of the §7
//! camera. Ray `index` belongs to pixel `morton_pixels[index / spp]` (Morton order
//! for coherence) and sample `index % spp`; its `sample` field is
//! `row-major pixel * spp + sample`, so scattering by it writes row-major output.
//! Camera rays have weight 1 and depth 0.

use crate::camera::{check_samples_per_pixel, sample_offset};
use crate::functors::{RayRecord, RayWriter};
use crate::scene::TraceResources;
use dpp_runtime::{
    ArrayParam, CallContext, Column, ColumnView, ElemType, Functor, FunctorError, FunctorKind,
    HostType, HostValue, NamedParam, RecordId, Signature, TypePattern,
};
use glam::Vec3;

pub struct CameraRay {
    signature: Signature,
}

impl CameraRay {
    pub fn new(ray: RecordId) -> CameraRay {
        CameraRay {
            signature: Signature {
                name: "cameraRay",
                kind: FunctorKind::Map,
                inputs: vec![ArrayParam {
                    name: "index",
                    ty: TypePattern::Exact(ElemType::U32),
                }],
                outputs: vec![ArrayParam {
                    name: "ray",
                    ty: TypePattern::Exact(ElemType::Record(ray)),
                }],
                named: vec![NamedParam {
                    name: "spp",
                    ty: HostType::Int,
                    default: Some(HostValue::Int(1)),
                    doc: "samples per pixel: 1 (pixel centre) or 4 (2x2 grid)",
                }],
                doc: "primary ray `index` of the camera (pixels in Morton order, spp samples each)",
            },
        }
    }
}

impl Functor for CameraRay {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let spp_value = ctx.named(0);
        let spp = spp_value
            .as_u32()
            .filter(|&spp| check_samples_per_pixel(spp).is_ok())
            .ok_or_else(|| {
                FunctorError(format!(
                    "cameraRay: spp must be 1 or 4 (the sample patterns of the camera), got {spp_value}"
                ))
            })?;
        let setup = &ctx.resources::<TraceResources>()?.camera;
        let camera = &setup.camera;
        let indices = inputs[0].as_u32();
        let mut rays = RayWriter::new(&mut outputs[0], indices.len())?;
        for &index in indices {
            let pixel = *setup
                .morton_pixels
                .get((index / spp) as usize)
                .ok_or_else(|| {
                    FunctorError(format!(
                        "cameraRay: ray index {index} is out of range for {} pixels x {spp} samples",
                        setup.morton_pixels.len()
                    ))
                })?;
            let sample_in_pixel = index % spp;
            let (sx, sy) = sample_offset(spp, sample_in_pixel);
            rays.push(RayRecord {
                origin: camera.eye,
                dir: camera.direction(pixel % camera.width, pixel / camera.width, sx, sy),
                tmax: f32::INFINITY,
                // Below 2^30: the camera caps pixels at 2^28 and spp at 4.
                sample: pixel * spp + sample_in_pixel,
                weight: Vec3::ONE,
                depth: 0,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use dpp_runtime::{Column, HostValue};
    use glam::Vec3;

    #[test]
    fn one_sample_per_pixel_in_morton_order() {
        let fixture = Fixture::new();
        let indices = Column::U32((0..12).collect());
        let out = fixture
            .run("cameraRay", &[HostValue::Int(1)], 0, &[indices.view()])
            .unwrap();
        let rays = out[0].view();
        let camera = &fixture.resources.camera;
        let samples = rays.field(3).as_u32();
        assert_eq!(samples, camera.morton_pixels.as_slice());
        for (i, &pixel) in samples.iter().enumerate() {
            let expected = camera.camera.direction(pixel % 4, pixel / 4, 0.5, 0.5);
            assert_eq!(rays.field(1).as_vec3()[i], expected);
            assert_eq!(rays.field(0).as_vec3()[i], Vec3::new(0.0, 0.0, 2.0));
            assert_eq!(rays.field(2).as_f32()[i], f32::INFINITY);
            assert_eq!(rays.field(4).as_vec3()[i], Vec3::ONE);
            assert_eq!(rays.field(5).as_u32()[i], 0);
        }
        // Morton order of a 4x3 image, as row-major indices.
        assert_eq!(samples, &[0, 1, 4, 5, 2, 3, 6, 7, 8, 9, 10, 11]);
    }

    #[test]
    fn four_samples_per_pixel_are_adjacent() {
        let fixture = Fixture::new();
        // A chunk in the middle: rays 8..16 are pixels morton[2] and morton[3].
        let indices = Column::U32((8..16).collect());
        let out = fixture
            .run("cameraRay", &[HostValue::Int(4)], 8, &[indices.view()])
            .unwrap();
        let rays = out[0].view();
        let samples = rays.field(3).as_u32();
        assert_eq!(samples, &[16, 17, 18, 19, 20, 21, 22, 23]);
        let camera = &fixture.resources.camera.camera;
        let offsets = [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)];
        for (i, &sample) in samples.iter().enumerate() {
            let pixel = sample / 4;
            let (sx, sy) = offsets[(sample % 4) as usize];
            assert_eq!(
                rays.field(1).as_vec3()[i],
                camera.direction(pixel % 4, pixel / 4, sx, sy)
            );
        }
    }

    #[test]
    fn bad_spp_and_out_of_range_index_are_errors() {
        let fixture = Fixture::new();
        let indices = Column::U32(vec![0, 1]);
        for spp in [0, 2, 3, 8, -1] {
            let error = fixture
                .run("cameraRay", &[HostValue::Int(spp)], 0, &[indices.view()])
                .unwrap_err();
            assert!(error.0.contains("spp must be 1 or 4"), "{error}");
        }
        let beyond = Column::U32(vec![12]);
        let error = fixture
            .run("cameraRay", &[HostValue::Int(1)], 0, &[beyond.view()])
            .unwrap_err();
        assert!(error.0.contains("out of range"), "{error}");
        let beyond = Column::U32(vec![47, 48]);
        assert!(fixture
            .run("cameraRay", &[HostValue::Int(4)], 0, &[beyond.view()])
            .is_err());
    }
}
