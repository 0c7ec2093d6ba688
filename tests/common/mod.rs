//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs the `dpp` binary with `args` in `dir`.
pub fn dpp(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dpp"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("dpp runs")
}

/// A program's output as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Whether the GPU backend can start here: `dpp run --backend gpu` on a tiny
/// example pipeline. Without an adapter it prints why `what` is skipped and
/// returns false, unless the environment variable `DPP_REQUIRE_GPU` is set (CI
/// sets it and installs Mesa's lavapipe): then the test fails.
pub fn gpu_available(what: &str) -> bool {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = repo().join("pipelines/examples/prefix_sum.dpp");
    let output = dpp(
        &["run", pipeline.to_str().unwrap(), "--backend", "gpu"],
        dir.path(),
    );
    if output.status.success() {
        return true;
    }
    let stderr = text(&output.stderr);
    if std::env::var_os("DPP_REQUIRE_GPU").is_some() {
        panic!("DPP_REQUIRE_GPU is set but the GPU backend failed: {stderr}");
    }
    eprintln!("skipping {what}: {stderr}");
    false
}

/// Every `.dpp` file under `pipelines/` that holds a pipeline (the prelude holds only fns).
pub fn pipeline_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "dpp")
                && std::fs::read_to_string(&path)
                    .unwrap()
                    .contains("pipeline ")
            {
                out.push(path);
            }
        }
    }
    let mut files = Vec::new();
    walk(&repo().join("pipelines"), &mut files);
    files.sort();
    files
}

/// `workload1`, `examples.histogram`: the path under `pipelines/` without extension.
pub fn pipeline_name(path: &Path) -> String {
    path.strip_prefix(repo().join("pipelines"))
        .unwrap()
        .with_extension("")
        .to_string_lossy()
        .replace('/', ".")
}

/// A floor (`floor`), a box standing on it (`box`) and a mirror behind it
/// (`mirror`, reflectivity 0.8), in that order.
pub const SCENE_OBJ: &str = "\
mtllib scene.mtl
usemtl floor
v -2 0 -2
v -2 0 2
v 2 0 2
v 2 0 -2
f 1 2 3 4
usemtl box
v -0.4 0 -0.4
v 0.4 0 -0.4
v 0.4 0.8 -0.4
v -0.4 0.8 -0.4
v -0.4 0 0.4
v 0.4 0 0.4
v 0.4 0.8 0.4
v -0.4 0.8 0.4
f 5 8 7 6
f 9 10 11 12
f 5 6 10 9
f 8 12 11 7
f 5 9 12 8
f 6 7 11 10
usemtl mirror
v -1.5 0 -1.5
v 1.5 0 -1.5
v 1.5 1.5 -1.5
v -1.5 1.5 -1.5
f 13 14 15 16
";

pub const SCENE_MTL: &str = "\
newmtl floor
Kd 0.8 0.8 0.8
Ks 0.1 0.1 0.1
Ns 16
newmtl box
Kd 0.9 0.45 0.3
Ks 0.5 0.5 0.5
Ns 64
newmtl mirror
Kd 0.2 0.2 0.2
Ks 0.9 0.9 0.9
Ns 128
refl 0.8
";

/// Camera and lighting of the small scene: seen from the front and above, one
/// light up and to the left, a light grey colour map (the scalar is the height).
pub const SCENE_VIEW: &[&str] = &[
    "--eye",
    "0.3,2.2,4",
    "--look-at",
    "0,0.4,-0.3",
    "--light=-2.5,3,1.5,1.5",
    "--colormap",
    "grey",
    "--scalar-range=-8,1",
];

/// An 8-bit sRGB image read from a PNG.
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Image {
    pub fn load(path: &Path) -> Image {
        let image = image::open(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .to_rgb8();
        Image {
            width: image.width(),
            height: image.height(),
            rgb: image.into_raw(),
        }
    }

    /// Linear-light luminance of pixel `i` (the PNG holds sRGB).
    pub fn luminance(&self, i: usize) -> f32 {
        let linear = |c: u8| {
            let c = c as f32 / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        };
        let p = &self.rgb[3 * i..3 * i + 3];
        0.2126 * linear(p[0]) + 0.7152 * linear(p[1]) + 0.0722 * linear(p[2])
    }

    pub fn pixels(&self) -> usize {
        (self.width * self.height) as usize
    }
}

/// A scratch folder holding the small scene.
pub fn scene_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.obj"), SCENE_OBJ).unwrap();
    std::fs::write(dir.path().join("scene.mtl"), SCENE_MTL).unwrap();
    dir
}

/// Mean FLIP error (0 for identical images, at most 1).
pub fn mean_flip(reference: &Image, test: &Image) -> f32 {
    assert_eq!(
        (reference.width, reference.height),
        (test.width, test.height)
    );
    let reference =
        nv_flip::FlipImageRgb8::with_data(reference.width, reference.height, &reference.rgb);
    let test = nv_flip::FlipImageRgb8::with_data(test.width, test.height, &test.rgb);
    let error = nv_flip::flip(reference, test, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    nv_flip::FlipPool::from_image(&error).mean()
}

/// The values of a `.npy` file.
pub fn read_npy<T: npyz::Deserialize>(path: &Path) -> Vec<T> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    npyz::NpyFile::new(&bytes[..]).unwrap().into_vec().unwrap()
}

/// Runs `pipelines/{pipeline}` with `args` in `dir`, which must succeed, and
/// returns the float arrays of its `outputs` (written as `.npy` files there).
pub fn run_pipeline_outputs(
    dir: &Path,
    pipeline: &str,
    args: &[&str],
    outputs: &[&str],
) -> Vec<Vec<f32>> {
    let pipeline = repo().join("pipelines").join(pipeline);
    let mut all: Vec<String> = vec!["run".into(), pipeline.display().to_string()];
    all.extend(args.iter().map(|a| a.to_string()));
    for name in outputs {
        all.extend(["--out".into(), format!("{name}={name}.npy")]);
    }
    let all: Vec<&str> = all.iter().map(String::as_str).collect();
    let output = dpp(&all, dir);
    assert!(
        output.status.success(),
        "dpp {all:?}: {}",
        text(&output.stderr)
    );
    outputs
        .iter()
        .map(|name| read_npy::<f32>(&dir.join(format!("{name}.npy"))))
        .collect()
}
