//! A surface inside a volume (`pipelines/volume_surface.dpp`) against the
//! volume alone (`pipelines/volume.dpp`) on the same generated sphere: each
//! ray's march stops at the isosurface it hits, so the volume's opacity in
//! front of it is at most what the whole ray gathers, and less where the
//! surface cuts the march short; where no surface is hit the march is the
//! same, bit for bit; and the surface makes its pixels opaque.

use crate::common::{dpp, repo, run_pipeline_outputs};
use std::path::Path;

/// Runs `pipeline` on a small generated sphere with `args`; returns the float
/// arrays of `outputs`.
fn run(dir: &Path, pipeline: &str, args: &[&str], outputs: &[&str]) -> Vec<Vec<f32>> {
    let mut all = vec!["sphere:32", "--size", "64x48", "--transfer", "viridis"];
    all.extend_from_slice(args);
    run_pipeline_outputs(dir, pipeline, &all, outputs)
}

#[test]
fn the_march_stops_at_the_surface_and_the_surface_is_opaque() {
    let dir = tempfile::tempdir().unwrap();
    let alone = &run(dir.path(), "volume.dpp", &[], &["alpha"])[0];
    let with = run(
        dir.path(),
        "volume_surface.dpp",
        &["--iso", "0.3"],
        &["alpha", "volumeAlpha"],
    );
    let (alpha, in_front) = (&with[0], &with[1]);
    let mut cut_short = 0;
    let mut surface = 0;
    for ((&whole, &front), &total) in alone.iter().zip(in_front).zip(alpha) {
        assert!(
            front <= whole,
            "the volume in front of the surface is denser than the whole ray"
        );
        assert!(total >= front);
        if total < 0.999 {
            // No surface on this ray: the same march.
            assert_eq!(front, whole);
        } else {
            surface += 1;
            cut_short += usize::from(front < whole - 1e-3);
        }
    }
    let pixels = alone.len();
    assert!(
        surface > pixels / 20,
        "the surface covers {surface} of {pixels} pixels"
    );
    assert!(
        cut_short > surface / 2,
        "the surface cut {cut_short} of {surface} marches short"
    );
}

#[test]
fn a_surface_pipeline_needs_its_level() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = repo().join("pipelines/volume_surface.dpp");
    let output = dpp(
        &[
            "run",
            pipeline.to_str().unwrap(),
            "sphere:12",
            "--size",
            "16x12",
        ],
        dir.path(),
    );
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("give the surface's level with --iso"),
        "{stderr}"
    );
}
