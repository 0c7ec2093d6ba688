//! The pinhole camera of the language reference (docs/language.md §8) and the
//! Morton order of its pixels.

use crate::bvh::Ray;
use crate::mesh::Bounds;
use crate::vector::unit_or_zero;
use glam::Vec3;
use std::str::FromStr;
use thiserror::Error;

/// Largest `width * height`: with at most [`MAX_SAMPLES_PER_PIXEL`] samples per
/// pixel, ray indices stay below 2^30 (u32 on every backend, with headroom).
pub const MAX_PIXELS: u64 = 1 << 28;
/// Samples per pixel the camera knows sample offsets for.
pub const MAX_SAMPLES_PER_PIXEL: u32 = 4;

#[derive(Clone, Debug, Error, PartialEq)]
pub enum CameraError {
    #[error("image size {width}x{height} is empty")]
    EmptyImage { width: u32, height: u32 },
    #[error("image size {width}x{height} has more than {MAX_PIXELS} pixels")]
    TooManyPixels { width: u32, height: u32 },
    #[error("field of view {0} degrees is not in (0, 180)")]
    BadFieldOfView(f32),
    #[error("camera vectors must be finite (eye {eye:?}, look_at {look_at:?}, up {up:?})")]
    NonFinite { eye: Vec3, look_at: Vec3, up: Vec3 },
    #[error("eye and look_at are the same point {0:?}")]
    EyeAtTarget(Vec3),
    #[error("up {up:?} is parallel to the viewing direction {forward:?}")]
    UpParallelToForward { up: Vec3, forward: Vec3 },
    #[error("{0} samples per pixel are not supported; use 1 or 4")]
    UnsupportedSamplesPerPixel(u32),
    #[error("unknown view `{0}`; the standard views are front, back and zoom")]
    UnknownView(String),
    #[error(
        "the scene's bounding box ({min:?} to {max:?}) is too large for a standard view: \
         its size overflows f32 (set the camera with --eye and --look-at)"
    )]
    SceneTooLarge { min: Vec3, max: Vec3 },
}

/// The standard views of docs/language.md §8.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StandardView {
    Front,
    Back,
    Zoom,
}

impl FromStr for StandardView {
    type Err = CameraError;

    fn from_str(name: &str) -> Result<Self, CameraError> {
        match name {
            "front" => Ok(StandardView::Front),
            "back" => Ok(StandardView::Back),
            "zoom" => Ok(StandardView::Zoom),
            other => Err(CameraError::UnknownView(other.to_string())),
        }
    }
}

/// A validated pinhole camera with its orthonormal frame precomputed.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub look_at: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_degrees: f32,
    pub width: u32,
    pub height: u32,
    pub(crate) forward: Vec3,
    pub(crate) right: Vec3,
    pub(crate) true_up: Vec3,
    /// `tan(fov / 2)`.
    pub(crate) half_height: f32,
    pub(crate) aspect: f32,
}

impl Camera {
    pub fn new(
        eye: Vec3,
        look_at: Vec3,
        up: Vec3,
        fov_degrees: f32,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyImage { width, height });
        }
        if u64::from(width) * u64::from(height) > MAX_PIXELS {
            return Err(CameraError::TooManyPixels { width, height });
        }
        if !(fov_degrees > 0.0 && fov_degrees < 180.0) {
            return Err(CameraError::BadFieldOfView(fov_degrees));
        }
        if !(eye.is_finite() && look_at.is_finite() && up.is_finite()) {
            return Err(CameraError::NonFinite { eye, look_at, up });
        }
        let towards = look_at - eye;
        if !towards.is_finite() {
            return Err(CameraError::NonFinite { eye, look_at, up });
        }
        let forward = unit_or_zero(towards);
        if forward == Vec3::ZERO {
            return Err(CameraError::EyeAtTarget(eye));
        }
        let right = unit_or_zero(forward.cross(up));
        if right == Vec3::ZERO {
            return Err(CameraError::UpParallelToForward { up, forward });
        }
        Ok(Camera {
            eye,
            look_at,
            up,
            fov_degrees,
            width,
            height,
            forward,
            right,
            true_up: right.cross(forward),
            half_height: (fov_degrees.to_radians() * 0.5).tan(),
            aspect: width as f32 / height as f32,
        })
    }

    /// A standard view of a scene: `up = +y`, `fov = 45`, looking at the centre `c`
    /// from `c + (0,0,d)` (front), `c - (0,0,d)` (back) or `c + (0,0,0.35 d)` (zoom).
    pub fn standard(
        view: StandardView,
        bounds: &Bounds,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        let center = bounds.center();
        let diagonal = bounds.diagonal();
        let offset = match view {
            StandardView::Front => Vec3::new(0.0, 0.0, diagonal),
            StandardView::Back => Vec3::new(0.0, 0.0, -diagonal),
            StandardView::Zoom => Vec3::new(0.0, 0.0, 0.35 * diagonal),
        };
        let eye = center + offset;
        if !(center.is_finite() && eye.is_finite()) {
            return Err(CameraError::SceneTooLarge {
                min: bounds.min,
                max: bounds.max,
            });
        }
        Camera::new(eye, center, Vec3::Y, 45.0, width, height)
    }

    pub fn pixels(&self) -> u32 {
        // Fits: `new` bounds it by MAX_PIXELS.
        self.width * self.height
    }

    /// The unit direction through offset `(sx, sy)` of pixel `(x, y)`, row 0 at the
    /// top (docs/language.md §8).
    #[inline]
    pub fn direction(&self, x: u32, y: u32, sx: f32, sy: f32) -> Vec3 {
        let horizontal = 2.0 * (x as f32 + sx) / self.width as f32 - 1.0;
        let vertical = 1.0 - 2.0 * (y as f32 + sy) / self.height as f32;
        (self.forward
            + horizontal * self.half_height * self.aspect * self.right
            + vertical * self.half_height * self.true_up)
            .normalize()
    }
}

/// The offset inside its pixel of sample `sample` of `samples_per_pixel`
/// (docs/language.md §8):
/// the centre for one sample, the 2×2 grid row by row for four.
#[inline]
pub fn sample_offset(samples_per_pixel: u32, sample: u32) -> (f32, f32) {
    if samples_per_pixel == 1 {
        (0.5, 0.5)
    } else {
        (
            0.25 + 0.5 * (sample & 1) as f32,
            0.25 + 0.5 * (sample >> 1) as f32,
        )
    }
}

/// Checks a samples-per-pixel count against the offsets [`sample_offset`] knows.
pub fn check_samples_per_pixel(samples_per_pixel: u32) -> Result<(), CameraError> {
    match samples_per_pixel {
        1 | 4 => Ok(()),
        other => Err(CameraError::UnsupportedSamplesPerPixel(other)),
    }
}

/// A camera with the Morton order of its pixels, shared by every ray-generation call.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraSetup {
    pub camera: Camera,
    /// Row-major pixel indices sorted by the Morton code of `(x, y)`: ray `i` with
    /// `spp` samples per pixel belongs to pixel `morton_pixels[i / spp]`.
    pub morton_pixels: Vec<u32>,
}

impl CameraSetup {
    pub fn new(camera: Camera) -> CameraSetup {
        let morton_pixels = morton_order(camera.width, camera.height);
        CameraSetup {
            camera,
            morton_pixels,
        }
    }

    /// One ray through each pixel's centre, in Morton order, unbounded: the
    /// coherent primary rays the traversal's packets are made for.
    pub fn pixel_centre_rays(&self) -> Vec<Ray> {
        let camera = &self.camera;
        self.morton_pixels
            .iter()
            .map(|&pixel| Ray {
                origin: camera.eye,
                direction: camera.direction(pixel % camera.width, pixel / camera.width, 0.5, 0.5),
                tmax: f32::INFINITY,
            })
            .collect()
    }

    /// The camera tracing only the pixels `traced` keeps (a rank's share of
    /// the image), still in Morton order: `camera.tracedPixels` rays then
    /// cover them, and the image keeps every pixel's slot.
    pub fn tracing_only(camera: Camera, traced: impl Fn(u32) -> bool) -> CameraSetup {
        let mut setup = CameraSetup::new(camera);
        setup.morton_pixels.retain(|&pixel| traced(pixel));
        setup
    }
}

/// Side of the square tiles that image decomposition deals out to ranks.
pub const TILE_SIZE: u32 = 32;

/// Which of `ranks` ranks traces `pixel` (row-major) under image
/// decomposition: tiles of [`TILE_SIZE`] dealt out in turn, row by row, so
/// that every rank gets some of every part of the image (balance without
/// knowing where the work is).
pub fn tile_owner(pixel: u32, width: u32, ranks: usize) -> usize {
    let (x, y) = (pixel % width, pixel / width);
    let tiles_per_row = width.div_ceil(TILE_SIZE);
    let tile = u64::from(y / TILE_SIZE) * u64::from(tiles_per_row) + u64::from(x / TILE_SIZE);
    (tile % ranks as u64) as usize
}

/// Row-major indices of a `width × height` image in Z-curve order (x in the even
/// bits of the code, y in the odd ones), for any size. Walks the quadtree of the
/// enclosing power-of-two square and skips quadrants outside the image, which
/// equals sorting by Morton code without computing or sorting codes.
pub fn morton_order(width: u32, height: u32) -> Vec<u32> {
    let mut order = Vec::with_capacity(width as usize * height as usize);
    if width == 0 || height == 0 {
        return order;
    }
    let side = width.max(height).next_power_of_two();
    visit_quadrant(0, 0, side, width, height, &mut order);
    order
}

fn visit_quadrant(x0: u32, y0: u32, side: u32, width: u32, height: u32, order: &mut Vec<u32>) {
    if x0 >= width || y0 >= height {
        return;
    }
    // Below a few pixels the recursion costs more than a direct Z walk of the block.
    if side <= 4 {
        for code in 0..side * side {
            let (dx, dy) = deinterleave(code);
            let (x, y) = (x0 + dx, y0 + dy);
            if x < width && y < height {
                order.push(y * width + x);
            }
        }
        return;
    }
    let half = side / 2;
    visit_quadrant(x0, y0, half, width, height, order);
    visit_quadrant(x0 + half, y0, half, width, height, order);
    visit_quadrant(x0, y0 + half, half, width, height, order);
    visit_quadrant(x0 + half, y0 + half, half, width, height, order);
}

/// `(x, y)` from a Morton code below 16 (x in the even bits).
fn deinterleave(code: u32) -> (u32, u32) {
    (
        (code & 1) | ((code >> 1) & 2),
        ((code >> 1) & 1) | ((code >> 2) & 2),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn interleave(x: u32, y: u32) -> u64 {
        let mut code = 0u64;
        for bit in 0..32 {
            code |= u64::from((x >> bit) & 1) << (2 * bit);
            code |= u64::from((y >> bit) & 1) << (2 * bit + 1);
        }
        code
    }

    fn sorted_by_code(width: u32, height: u32) -> Vec<u32> {
        let mut pixels: Vec<u32> = (0..width * height).collect();
        pixels.sort_by_key(|&p| interleave(p % width, p / width));
        pixels
    }

    #[test]
    fn morton_order_of_small_images() {
        assert_eq!(morton_order(4, 2), vec![0, 1, 4, 5, 2, 3, 6, 7]);
        assert_eq!(morton_order(3, 3), vec![0, 1, 3, 4, 2, 5, 6, 7, 8]);
        assert_eq!(morton_order(1, 3), vec![0, 1, 2]);
    }

    #[test]
    fn morton_order_is_a_permutation_sorted_by_code() {
        for (width, height) in [(1, 1), (7, 5), (16, 16), (33, 9), (5, 40), (100, 3)] {
            let order = morton_order(width, height);
            assert_eq!(order, sorted_by_code(width, height), "{width}x{height}");
            let mut seen = order.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..width * height).collect::<Vec<_>>());
        }
    }

    fn expected_direction(camera: &Camera, x: f32, y: f32) -> Vec3 {
        // docs/language.md §8, spelled out independently of the precomputed frame.
        let f = (camera.look_at - camera.eye).normalize();
        let r = f.cross(camera.up).normalize();
        let u = r.cross(f);
        let t = (camera.fov_degrees.to_radians() / 2.0).tan();
        let aspect = camera.width as f32 / camera.height as f32;
        (f + (2.0 * x / camera.width as f32 - 1.0) * t * aspect * r
            + (1.0 - 2.0 * y / camera.height as f32) * t * u)
            .normalize()
    }

    #[test]
    fn directions_follow_the_spec_formula() {
        let camera = Camera::new(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-1.0, 0.5, -2.0),
            Vec3::Y,
            60.0,
            64,
            48,
        )
        .unwrap();
        for (x, y, sx, sy) in [
            (0, 0, 0.0, 0.0),
            (63, 47, 1.0, 1.0),
            (0, 47, 0.0, 1.0),
            (32, 24, 0.0, 0.0),
            (10, 20, 0.25, 0.75),
        ] {
            let got = camera.direction(x, y, sx, sy);
            let want = expected_direction(&camera, x as f32 + sx, y as f32 + sy);
            assert!((got - want).length() < 1e-6, "{x},{y}: {got} vs {want}");
        }
    }

    #[test]
    fn corners_and_centre_of_an_axis_aligned_camera() {
        // Looking down -z with fov 90: tan(45°) = 1, so the image plane at z = -1 spans
        // x in [-aspect, aspect] and y in [-1, 1], +y at the top row.
        let camera = Camera::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90.0, 4, 2).unwrap();
        let aspect = 2.0;
        let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-6;
        assert!(close(camera.direction(2, 1, 0.0, 0.0), Vec3::NEG_Z));
        assert!(close(
            camera.direction(0, 0, 0.0, 0.0),
            Vec3::new(-aspect, 1.0, -1.0).normalize()
        ));
        assert!(close(
            camera.direction(3, 1, 1.0, 1.0),
            Vec3::new(aspect, -1.0, -1.0).normalize()
        ));
    }

    #[test]
    fn sample_offsets() {
        assert_eq!(sample_offset(1, 0), (0.5, 0.5));
        let grid: Vec<_> = (0..4).map(|s| sample_offset(4, s)).collect();
        assert_eq!(
            grid,
            vec![(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)]
        );
        assert!(check_samples_per_pixel(1).is_ok());
        assert!(check_samples_per_pixel(4).is_ok());
        assert_eq!(
            check_samples_per_pixel(2),
            Err(CameraError::UnsupportedSamplesPerPixel(2))
        );
    }

    #[test]
    fn standard_views() {
        let bounds = Bounds {
            min: Vec3::new(-1.0, 0.0, 2.0),
            max: Vec3::new(1.0, 2.0, 4.0),
        };
        let d = bounds.diagonal();
        let c = Vec3::new(0.0, 1.0, 3.0);
        let front = Camera::standard(StandardView::Front, &bounds, 8, 8).unwrap();
        assert_eq!(front.eye, c + Vec3::new(0.0, 0.0, d));
        assert_eq!(front.look_at, c);
        assert_eq!(front.up, Vec3::Y);
        assert_eq!(front.fov_degrees, 45.0);
        let back = Camera::standard("back".parse().unwrap(), &bounds, 8, 8).unwrap();
        assert_eq!(back.eye, c - Vec3::new(0.0, 0.0, d));
        let zoom = Camera::standard("zoom".parse().unwrap(), &bounds, 8, 8).unwrap();
        assert_eq!(zoom.eye, c + Vec3::new(0.0, 0.0, 0.35 * d));
        assert!("side".parse::<StandardView>().is_err());
        // Far-apart eye and target (their distance squared overflows f32) still
        // make a camera, and a box 1e30 across has a standard view; one whose
        // size overflows f32 has none.
        let far = Camera::new(Vec3::new(0.0, 0.0, 3e30), Vec3::ZERO, Vec3::Y, 45.0, 8, 8).unwrap();
        assert_eq!(far.direction(4, 4, 0.0, 0.0), Vec3::NEG_Z);
        let large = Bounds {
            min: Vec3::ZERO,
            max: Vec3::splat(1e30),
        };
        assert!(Camera::standard(StandardView::Front, &large, 8, 8).is_ok());
        let huge = Bounds {
            min: Vec3::splat(-3e38),
            max: Vec3::splat(3e38),
        };
        assert!(matches!(
            Camera::standard(StandardView::Front, &huge, 8, 8),
            Err(CameraError::SceneTooLarge { .. })
        ));
    }

    #[test]
    fn invalid_cameras_are_rejected() {
        let make = |eye: Vec3, up: Vec3, fov: f32, w: u32, h: u32| {
            Camera::new(eye, Vec3::ZERO, up, fov, w, h)
        };
        let eye = Vec3::Z;
        assert!(matches!(
            make(eye, Vec3::Y, 45.0, 0, 10),
            Err(CameraError::EmptyImage { .. })
        ));
        assert!(matches!(
            make(eye, Vec3::Y, 45.0, 1 << 15, 1 << 14),
            Err(CameraError::TooManyPixels { .. })
        ));
        assert!(make(eye, Vec3::Y, 45.0, 1 << 14, 1 << 14).is_ok());
        assert!(matches!(
            make(eye, Vec3::Y, 45.0, u32::MAX, u32::MAX),
            Err(CameraError::TooManyPixels { .. })
        ));
        assert!(matches!(
            make(eye, Vec3::Y, 180.0, 4, 4),
            Err(CameraError::BadFieldOfView(_))
        ));
        assert!(matches!(
            make(eye, Vec3::Y, f32::NAN, 4, 4),
            Err(CameraError::BadFieldOfView(_))
        ));
        assert!(matches!(
            make(Vec3::ZERO, Vec3::Y, 45.0, 4, 4),
            Err(CameraError::EyeAtTarget(_))
        ));
        assert!(matches!(
            make(eye, Vec3::Z, 45.0, 4, 4),
            Err(CameraError::UpParallelToForward { .. })
        ));
        assert!(matches!(
            make(Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::Y, 45.0, 4, 4),
            Err(CameraError::NonFinite { .. })
        ));
    }
}
