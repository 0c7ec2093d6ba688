//! `cameraRay(index: u32) -> (ray: Ray) [spp: int = 1]`: primary rays of the
//! camera of docs/language.md §8. Ray `index` belongs to pixel
//! `morton_pixels[index / spp]` (Morton order for coherence) and sample
//! `index % spp`; its `sample` field is `row-major pixel * spp + sample`, so
//! scattering by it writes row-major output.
//! Camera rays have weight 1 and depth 0.

use crate::camera::{check_samples_per_pixel, sample_offset, Camera};
use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, vector_module, TwinParts};
use crate::functors::{RayRecord, RayWriter};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use glam::Vec3;
use std::sync::Arc;

pub fn functor(ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("cameraRay")
        .input("index", ElemType::U32)
        .output("ray", ElemType::Record(ray))
        .named(
            "spp",
            HostType::Int,
            Some(HostValue::Int(1)),
            "samples per pixel: 1 (pixel centre) or 4 (2x2 grid)",
        )
        .doc("primary ray `index` of the camera (pixels in Morton order, spp samples each)");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the camera frame and Morton order built once per camera.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let camera = request_resources::<TraceResources>(request, "cameraRay")?.camera_gpu_buffers();
    Ok(TwinParts {
        modules: vec![vector_module()],
        buffers: vec![camera.camera, camera.morton_pixels],
        failures: vec![
            "cameraRay: spp must be 1 or 4 (the sample patterns of the camera)".into(),
            "cameraRay: a ray index is out of range for the camera's pixels x spp samples".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let spp_value = ctx.named(0);
    let spp = spp_value
        .as_u32()
        .filter(|&spp| check_samples_per_pixel(spp).is_ok())
        .ok_or_else(|| {
            FunctorError::bad_input(format!(
                "cameraRay: spp must be 1 or 4 (the sample patterns of the camera), got {spp_value}"
            ))
        })?;
    let setup = &ctx.resources::<TraceResources>()?.camera;
    let camera = &setup.camera;
    let morton = setup.morton_pixels.as_slice();
    let indices = inputs[0].as_u32();
    // Ray `index` is valid while `index / spp < morton.len()`. One check of
    // the chunk's largest index up front keeps the loop free of errors.
    let limit = morton.len() as u64 * u64::from(spp);
    if indices
        .iter()
        .max()
        .is_some_and(|&max| u64::from(max) >= limit)
    {
        let index = indices
            .iter()
            .find(|&&index| u64::from(index) >= limit)
            .expect("the largest index is out of range");
        return Err(FunctorError::bad_input(format!(
            "cameraRay: ray index {index} is out of range for {} pixels x {spp} samples",
            morton.len()
        )));
    }
    // spp is 1 or 4: a shift and a mask split an index into pixel and sample.
    let shift = spp.trailing_zeros();
    let mask = spp - 1;
    let mut offsets = [(0.0, 0.0); 4];
    for (sample, offset) in offsets.iter_mut().enumerate().take(spp as usize) {
        *offset = sample_offset(spp, sample as u32);
    }
    let by_width = Divisor::new(camera.width);
    let pixel_and_offset = |index: u32| {
        let pixel = morton[(index >> shift) as usize];
        let (sx, sy) = offsets[(index & mask) as usize];
        let y = by_width.divide(pixel);
        (pixel - y * camera.width, y, sx, sy)
    };
    let mut block = Directions::new();
    let mut rays = RayWriter::new(&mut outputs[0], indices.len())?;
    rays.extend_with(indices.len(), |i| {
        let lane = i % LANES;
        if lane == 0 {
            block.compute(
                camera,
                &indices[i..indices.len().min(i + LANES)],
                pixel_and_offset,
            );
        }
        let index = indices[i];
        let pixel = morton[(index >> shift) as usize];
        RayRecord {
            origin: camera.eye,
            dir: block.get(lane),
            tmax: f32::INFINITY,
            // Below 2^30: the camera caps pixels at 2^28 and spp at 4.
            sample: (pixel << shift) | (index & mask),
            weight: Vec3::ONE,
            depth: 0,
        }
    });
    Ok(())
}

/// Rays whose directions are computed together: the lanes of a block run the
/// same arithmetic side by side, which the compiler turns into SIMD (the
/// divisions and square roots are what costs).
const LANES: usize = 64;

/// The directions of up to [`LANES`] rays, one array per component.
struct Directions {
    x: [f32; LANES],
    y: [f32; LANES],
    z: [f32; LANES],
}

impl Directions {
    fn new() -> Directions {
        let zeros = [0.0; LANES];
        Directions {
            x: zeros,
            y: zeros,
            z: zeros,
        }
    }

    /// The directions of rays `indices` (at most [`LANES`]), `pixel_and_offset`
    /// giving each one's pixel column and row and offset in the pixel.
    #[inline(always)]
    fn compute(
        &mut self,
        camera: &Camera,
        indices: &[u32],
        pixel_and_offset: impl Fn(u32) -> (u32, u32, f32, f32),
    ) {
        // Lanes past the end stay at pixel (0, 0): computed, never read.
        let (mut px, mut py) = ([0u32; LANES], [0u32; LANES]);
        let (mut sx, mut sy) = ([0f32; LANES], [0f32; LANES]);
        for (lane, &index) in indices.iter().enumerate().take(LANES) {
            (px[lane], py[lane], sx[lane], sy[lane]) = pixel_and_offset(index);
        }
        for lane in 0..LANES {
            let dir = camera.direction(px[lane], py[lane], sx[lane], sy[lane]);
            (self.x[lane], self.y[lane], self.z[lane]) = (dir.x, dir.y, dir.z);
        }
    }

    #[inline(always)]
    fn get(&self, lane: usize) -> Vec3 {
        Vec3::new(self.x[lane], self.y[lane], self.z[lane])
    }
}

/// Division of `u32`s by a fixed divisor as a multiplication (Lemire, Kaser and
/// Kurz, "Faster remainder by direct computation", 2019): with
/// `m = ceil(2^64 / d)`, `n / d = (m * n) >> 64` for every `u32` `n` and `d > 1`.
#[derive(Clone, Copy)]
struct Divisor {
    /// `ceil(2^64 / d)`; 0 for `d = 1` (whose `m`, 2^64, does not fit).
    multiplier: u64,
}

impl Divisor {
    fn new(divisor: u32) -> Divisor {
        assert!(divisor > 0, "division by zero");
        let multiplier = if divisor == 1 {
            0
        } else {
            u64::MAX / u64::from(divisor) + 1
        };
        Divisor { multiplier }
    }

    #[inline(always)]
    fn divide(self, n: u32) -> u32 {
        if self.multiplier == 0 {
            n
        } else {
            ((u128::from(self.multiplier) * u128::from(n)) >> 64) as u32
        }
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
    fn divisor_divides_exactly() {
        let mut n = 0x2545_f491u32;
        for d in [
            1,
            2,
            3,
            4,
            7,
            640,
            1000,
            1920,
            3840,
            65_535,
            1 << 28,
            u32::MAX,
        ] {
            let divisor = super::Divisor::new(d);
            for edge in [0, 1, d - 1, d, d.wrapping_add(1), u32::MAX - 1, u32::MAX] {
                assert_eq!(divisor.divide(edge), edge / d, "{edge} / {d}");
            }
            for _ in 0..10_000 {
                // xorshift32
                n ^= n << 13;
                n ^= n >> 17;
                n ^= n << 5;
                assert_eq!(divisor.divide(n), n / d, "{n} / {d}");
                let small = n >> 4;
                assert_eq!(divisor.divide(small), small / d, "{small} / {d}");
            }
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
            assert!(error.message.contains("spp must be 1 or 4"), "{error}");
        }
        let beyond = Column::U32(vec![12]);
        let error = fixture
            .run("cameraRay", &[HostValue::Int(1)], 0, &[beyond.view()])
            .unwrap_err();
        assert!(error.message.contains("out of range"), "{error}");
        let beyond = Column::U32(vec![47, 48]);
        assert!(fixture
            .run("cameraRay", &[HostValue::Int(4)], 0, &[beyond.view()])
            .is_err());
    }
}
