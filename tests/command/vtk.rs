//! VTK files through the command: the same data through different doors
//! gives the same image, parallel files render their pieces, and bad files
//! are errors (exit status 2) that name the file. The fixtures in
//! `tests/vtk/` were written by VTK itself (`scripts/make-vtk-fixtures.py`).

use crate::common::{dpp, read_npy, repo, text};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> String {
    repo().join("tests/vtk").join(name).display().to_string()
}

fn pipeline(name: &str) -> String {
    repo().join("pipelines").join(name).display().to_string()
}

/// Runs `dpp run PIPELINE SCENES… ARGS…` in `dir`, writing `OUTPUT` to
/// `FILE.npy`; returns the values.
fn run<T: npyz::Deserialize>(dir: &Path, args: &[&str], output: &str, file: &str) -> Vec<T> {
    let out = format!("{output}={file}.npy");
    let mut all = vec!["run"];
    all.extend(args);
    all.extend(["--size", "48x36", "--out", &out, "-o", "image.png", "-q"]);
    let result = dpp(&all, dir);
    assert!(
        result.status.success(),
        "{args:?}: {}",
        text(&result.stderr)
    );
    read_npy(&dir.join(format!("{file}.npy")))
}

#[test]
fn a_volume_through_every_door_gives_the_same_isosurface() {
    let dir = tempfile::tempdir().unwrap();
    let w2 = pipeline("workload2.dpp");
    let depth = |name: &str| -> Vec<f32> {
        run(
            dir.path(),
            &[&w2, &fixture(name), "--iso", "1.5"],
            "depth",
            name,
        )
    };
    let reference = depth("ball.nii.gz");
    assert!(reference.iter().filter(|d| d.is_finite()).count() > reference.len() / 10);
    for name in [
        "ball_ascii.vti",
        "ball_binary.vti",
        "ball_appended.vti",
        "ball_zlib.vti",
        "ball_lz4.vti",
        "ball_be.vti",
        "ball.pvti",
        "ball_legacy_binary.vtk",
    ] {
        let same = depth(name);
        assert!(
            same.iter()
                .zip(&reference)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{name}'s depth differs from the NIfTI file's"
        );
    }
    // Legacy ASCII keeps 6 significant digits: the surface moves a little.
    let ascii = depth("ball_legacy.vtk");
    let hits = |d: &[f32]| d.iter().map(|v| v.is_finite()).collect::<Vec<_>>();
    assert_eq!(hits(&ascii), hits(&reference));
    for (a, b) in ascii.iter().zip(&reference).filter(|(a, _)| a.is_finite()) {
        assert!((a - b).abs() < 1e-3 * b.abs().max(1.0), "{a} vs {b}");
    }
}

#[test]
fn a_mesh_through_every_door_gives_the_same_prims() {
    let dir = tempfile::tempdir().unwrap();
    let w1 = pipeline("workload1.dpp");
    let prims = |name: &str| -> Vec<u32> { run(dir.path(), &[&w1, &fixture(name)], "prim", name) };
    let reference = prims("shape.obj");
    assert!(reference.iter().filter(|&&p| p != u32::MAX).count() > reference.len() / 10);
    for name in [
        "shape.vtp",
        "shape_legacy.vtk",
        "shape_legacy_binary.vtk",
        "shape_legacy42.vtk",
    ] {
        assert_eq!(prims(name), reference, "{name}");
    }
}

#[test]
fn a_parallel_grid_renders_its_pieces_external_faces() {
    let dir = tempfile::tempdir().unwrap();
    let w1 = pipeline("workload1.dpp");
    let whole: Vec<u32> = run(dir.path(), &[&w1, &fixture("cells.pvtu")], "prim", "whole");
    let pieces: Vec<u32> = run(
        dir.path(),
        &[
            &w1,
            &fixture("cells/cells_0.vtu"),
            &fixture("cells/cells_1.vtu"),
        ],
        "prim",
        "pieces",
    );
    assert_eq!(whole, pieces);
    // The pieces' external surfaces, as VTK counts them (expected.json).
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    let triangles: u64 = (expected["cells"]["piece_surface_triangles"]
        .as_array()
        .unwrap())
    .iter()
    .map(|n| n.as_u64().unwrap())
    .sum();
    let hit: Vec<u32> = whole.iter().copied().filter(|&p| p != u32::MAX).collect();
    assert!(hit.len() > whole.len() / 10);
    assert!(
        hit.iter().all(|&p| (p as u64) < triangles),
        "{:?}",
        hit.iter().max()
    );
    // Every piece shows (its ids follow the first piece's).
    let first: u64 = expected["cells"]["piece_surface_triangles"][0]
        .as_u64()
        .unwrap();
    assert!(hit.iter().any(|&p| (p as u64) < first) && hit.iter().any(|&p| (p as u64) >= first));
    // Coloured by the cell field by default (the active scalars), by a
    // point field when asked.
    let (w2, cells) = (pipeline("workload2.dpp"), fixture("cells.pvtu"));
    let colours = |field: &[&str]| -> Vec<u8> {
        let mut args = vec!["run", &w2, &cells, "--size", "48x36", "-o", "c.png", "-q"];
        args.extend(field);
        let result = dpp(&args, dir.path());
        assert!(result.status.success(), "{}", text(&result.stderr));
        std::fs::read(dir.path().join("c.png")).unwrap()
    };
    let by_cell = colours(&[]);
    assert_eq!(colours(&["--field", "pressure"]), by_cell);
    assert_ne!(colours(&["--field", "temperature"]), by_cell);
}

fn fails(dir: &Path, args: &[&str], words: &[&str]) {
    let result = dpp(args, dir);
    let stderr = text(&result.stderr);
    assert_eq!(result.status.code(), Some(2), "{args:?}: {stderr}");
    for word in words {
        assert!(stderr.contains(word), "{args:?}: `{word}` not in {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
}

fn copy(from: &str, to: &Path) -> PathBuf {
    std::fs::copy(fixture(from), to).unwrap();
    to.to_path_buf()
}

#[test]
fn bad_vtk_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let at = dir.path();
    let w1 = pipeline("workload1.dpp");
    let w2 = pipeline("workload2.dpp");
    // A parallel file without its pieces.
    copy("cells.pvtu", &at.join("cells.pvtu"));
    fails(
        at,
        &["run", &w1, "cells.pvtu"],
        &["cells.pvtu", "cells_0.vtu", "missing"],
    );
    // An unknown field lists the arrays there are.
    fails(
        at,
        &["run", &w1, &fixture("cells.vtu"), "--field", "nope"],
        &[
            "cells.vtu",
            "nope",
            "pressure (cells)",
            "temperature (points)",
        ],
    );
    fails(
        at,
        &["run", &w1, &fixture("shape.obj"), "--field", "x"],
        &["--field x"],
    );
    // A NaN-laden field is no isosurface.
    let nan = "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\">\n\
        <ImageData WholeExtent=\"0 1 0 1 0 1\" Origin=\"0 0 0\" Spacing=\"1 1 1\">\n\
        <Piece Extent=\"0 1 0 1 0 1\"><PointData Scalars=\"f\">\n\
        <DataArray type=\"Float32\" Name=\"f\" format=\"ascii\">0 1 2 nan 4 5 6 7</DataArray>\n\
        </PointData><CellData></CellData></Piece></ImageData></VTKFile>\n";
    std::fs::write(at.join("nan.vti"), nan).unwrap();
    fails(
        at,
        &["run", &w2, "nan.vti", "--iso", "3"],
        &["nan.vti", "sample 3", "not finite"],
    );
    // Raw appended data, which vtkio cannot read.
    fails(
        at,
        &["run", &w2, &fixture("ball_raw.vti"), "--iso", "1"],
        &["ball_raw.vti", "raw"],
    );
    // A cell type dpp does not read.
    let quadratic =
        "# vtk DataFile Version 4.2\nq\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n\
        0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n24\n";
    std::fs::write(at.join("quadratic.vtk"), quadratic).unwrap();
    fails(
        at,
        &["run", &w1, "quadratic.vtk"],
        &["quadratic.vtk", "QuadraticTetra"],
    );
}

#[test]
fn iso_takes_a_vtk_field() {
    let dir = tempfile::tempdir().unwrap();
    let result = dpp(
        &[
            "iso",
            &fixture("ball_appended.vti"),
            "--field",
            "position:0",
            "--level",
            "0.3",
            "-o",
            "plane.ply",
        ],
        dir.path(),
    );
    assert!(result.status.success(), "{}", text(&result.stderr));
    let mesh = dpp_tracer::ply::load_ply(&dir.path().join("plane.ply")).unwrap();
    // The level set x = 0.3 of the position's first component is a plane.
    assert!(mesh.positions.iter().all(|p| (p.x - 0.3).abs() < 1e-5));
}
