//! `mpirun -n N dpp run …` against the single process (no `mpirun`): WORKLOAD1's
//! depth and triangle ids, WORKLOAD2's and WORKLOAD3's images, each rank's
//! share of the triangles, and failures on one rank that must end the whole
//! run with one status.
//!
//! Built only with `--features mpi` (tests/command/main.rs; Open MPI's
//! `mpirun` must be on the PATH).
//! Every `mpirun` runs under a deadline ([`RUN_TIMEOUT`]): a hang fails the
//! test instead of stalling CI. Run as root (CI containers), `mpirun` needs
//! `OMPI_ALLOW_RUN_AS_ROOT`, which [`mpirun`] sets.

use crate::common::{mean_flip, read_npy, repo, Image};

use std::fmt::Write as _;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The longest one `dpp run` or `mpirun` may take. The slowest here takes about
/// a second alone; this leaves room for a 2-core machine busy with other tests.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// Largest mean FLIP error (0 for identical images, 1 at most) between a
/// distributed image and the single process's where the renderer promises the
/// same image: the golden images' tolerance (tests/command/images.rs).
const FLIP_TOLERANCE: f32 = 0.005;

/// At most this fraction of the hit pixels may see a different triangle id
/// than the single process (exact depth ties, see [`compare_workload1`]).
const TIE_FRACTION: f64 = 0.005;

const MISS: u32 = u32::MAX;

fn pipeline(name: &str) -> String {
    repo().join("pipelines").join(name).display().to_string()
}

/// What a finished command left: its exit status and output.
struct Outcome {
    what: String,
    code: Option<i32>,
    stdout: String,
    stderr: String,
    elapsed: Duration,
}

impl Outcome {
    fn success(self) -> Outcome {
        assert_eq!(
            self.code,
            Some(0),
            "{} failed after {:.1?}:\n{}",
            self.what,
            self.elapsed,
            self.stderr
        );
        self
    }
}

/// Runs `command` in `dir` under [`RUN_TIMEOUT`]: past the deadline the
/// command (and its process group: `mpirun`'s ranks) is killed and the test
/// fails with what it printed.
fn run_with_deadline(mut command: Command, dir: &Path, what: String) -> Outcome {
    let log = tempfile::tempdir().unwrap();
    let (out_path, err_path) = (log.path().join("stdout"), log.path().join("stderr"));
    let start = Instant::now();
    let mut child = command
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .process_group(0)
        .spawn()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > RUN_TIMEOUT {
            // mpirun passes SIGTERM on to its ranks; then kill the whole group.
            let group = format!("-{}", child.id());
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
            std::thread::sleep(Duration::from_secs(3));
            let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{what} did not end within {RUN_TIMEOUT:?} (killed):\n{}",
                std::fs::read_to_string(&err_path).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Outcome {
        what,
        code: status.code(),
        stdout: std::fs::read_to_string(&out_path).unwrap(),
        stderr: std::fs::read_to_string(&err_path).unwrap(),
        elapsed: start.elapsed(),
    }
}

/// `dpp ARGS` in `dir`, one process.
fn single(dir: &Path, args: &[&str]) -> Outcome {
    let mut command = Command::new(env!("CARGO_BIN_EXE_dpp"));
    command.args(args);
    run_with_deadline(command, dir, format!("dpp {}", args.join(" ")))
}

/// `mpirun` with one `dpp ARGS` per entry of `programs` (MPMD: `-n K dpp … :
/// -n K dpp …`), in `dir`.
fn mpirun_mpmd(dir: &Path, programs: &[(usize, &[&str])]) -> Outcome {
    let mut command = Command::new("mpirun");
    command
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .args(["--oversubscribe", "--bind-to", "none"]);
    let mut what = "mpirun".to_string();
    for (i, (ranks, args)) in programs.iter().enumerate() {
        if i > 0 {
            command.arg(":");
            what.push_str(" :");
        }
        command
            .args(["-n", &ranks.to_string(), env!("CARGO_BIN_EXE_dpp")])
            .args(*args);
        write!(what, " -n {ranks} dpp {}", args.join(" ")).unwrap();
    }
    run_with_deadline(command, dir, what)
}

/// `mpirun -n RANKS dpp ARGS` in `dir`.
fn mpirun(dir: &Path, ranks: usize, args: &[&str]) -> Outcome {
    mpirun_mpmd(dir, &[(ranks, args)])
}

/// WORKLOAD1's depth and triangle ids.
struct Hits {
    depth: Vec<f32>,
    prim: Vec<u32>,
}

/// WORKLOAD1 on `scene` at 96x64, one process (`ranks` = None) or under
/// `mpirun -n ranks`.
fn workload1(dir: &Path, scene: &[&str], ranks: Option<usize>) -> Hits {
    let tag = ranks.map_or("single".to_string(), |n| format!("n{n}"));
    let (depth, prim) = (format!("depth_{tag}.npy"), format!("prim_{tag}.npy"));
    let (depth_out, prim_out) = (format!("depth={depth}"), format!("prim={prim}"));
    let w1 = pipeline("workload1.dpp");
    let mut args = vec!["run", &w1];
    args.extend_from_slice(scene);
    args.extend_from_slice(&[
        "--size", "96x64", "--out", &depth_out, "--out", &prim_out, "-o", "w1.png",
    ]);
    match ranks {
        None => single(dir, &args),
        Some(n) => mpirun(dir, n, &args),
    }
    .success();
    Hits {
        depth: read_npy(&dir.join(depth)),
        prim: read_npy(&dir.join(prim)),
    }
}

/// Checks a distributed WORKLOAD1 against the single process: the depth equal
/// (bit for bit) on every pixel; the triangle id equal except on exact ties.
///
/// The tie rule: two triangles at exactly the same distance along a ray are
/// resolved by each BVH's own traversal order, and a rank's BVH holds only its
/// part, so another triangle of the tie may win. A pixel whose id differs
/// counts as a tie only if it is a hit in both runs at the same depth (bit for
/// bit); every other difference fails, and ties may be at most
/// [`TIE_FRACTION`] of the hit pixels. Returns (ties, hit pixels).
fn compare_workload1(what: &str, single: &Hits, distributed: &Hits) -> (usize, usize) {
    assert_eq!(single.depth.len(), distributed.depth.len(), "{what}");
    assert_eq!(single.prim.len(), distributed.prim.len(), "{what}");
    let depth_differs = (single.depth.iter().zip(&distributed.depth))
        .filter(|(a, b)| a.to_bits() != b.to_bits())
        .count();
    assert_eq!(
        depth_differs, 0,
        "{what}: depth differs from the single process on {depth_differs} pixels"
    );
    let hits = single.prim.iter().filter(|&&p| p != MISS).count();
    assert!(hits > 100, "{what}: only {hits} pixels hit the scene");
    let mut ties = 0;
    for (i, (&a, &b)) in single.prim.iter().zip(&distributed.prim).enumerate() {
        if a == b {
            continue;
        }
        assert!(
            a != MISS && b != MISS && single.depth[i].to_bits() == distributed.depth[i].to_bits(),
            "{what}: pixel {i}: triangle {b} instead of {a}, depth {} instead of {}: not a tie",
            distributed.depth[i],
            single.depth[i]
        );
        ties += 1;
    }
    assert!(
        ties as f64 <= TIE_FRACTION * hits as f64,
        "{what}: {ties} of {hits} hit pixels see another triangle (more than {TIE_FRACTION})"
    );
    eprintln!("{what}: {ties} ties of {hits} hit pixels");
    (ties, hits)
}

/// WORKLOAD1 for N = 1..4 ranks against the single process on `scene`.
fn workload1_on_every_rank_count(dir: &Path, scene: &[&str]) {
    let reference = workload1(dir, scene, None);
    for ranks in 1..=4 {
        let distributed = workload1(dir, scene, Some(ranks));
        compare_workload1(
            &format!("WORKLOAD1 on {} with {ranks} ranks", scene.join(" ")),
            &reference,
            &distributed,
        );
    }
}

#[test]
fn workload1_on_a_volume_matches_one_process() {
    let dir = tempfile::tempdir().unwrap();
    workload1_on_every_rank_count(dir.path(), &["sphere:32"]);
    workload1_on_every_rank_count(dir.path(), &["rm:40"]);
}

/// Volume files are read brick by brick: each rank seeks to its own rows of
/// an uncompressed NIfTI file, or streams a gzipped one up to its brick.
#[test]
fn workload1_on_volume_files_read_by_brick_matches_one_process() {
    let dir = tempfile::tempdir().unwrap();
    for file in ["rm.nii", "rm.nii.gz"] {
        single(dir.path(), &["gen", "rm", "--grid", "33,29,25", "-o", file]).success();
        workload1_on_every_rank_count(dir.path(), &[file, "--iso", "128"]);
    }
}

/// A UV sphere as (vertices, triangles): `stacks` ≥ 2 bands, `slices` around.
fn uv_sphere(
    centre: [f32; 3],
    radius: f32,
    stacks: u32,
    slices: u32,
) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut vertices = vec![[centre[0], centre[1] + radius, centre[2]]];
    for stack in 1..stacks {
        let theta = std::f32::consts::PI * stack as f32 / stacks as f32;
        for slice in 0..slices {
            let phi = std::f32::consts::TAU * slice as f32 / slices as f32;
            vertices.push([
                centre[0] + radius * theta.sin() * phi.cos(),
                centre[1] + radius * theta.cos(),
                centre[2] + radius * theta.sin() * phi.sin(),
            ]);
        }
    }
    let south = vertices.len() as u32;
    vertices.push([centre[0], centre[1] - radius, centre[2]]);
    let ring = |stack: u32, slice: u32| 1 + (stack - 1) * slices + slice % slices;
    let mut triangles = Vec::new();
    for slice in 0..slices {
        triangles.push([0, ring(1, slice + 1), ring(1, slice)]);
        for stack in 1..stacks - 1 {
            let (a, b) = (ring(stack, slice), ring(stack, slice + 1));
            let (c, d) = (ring(stack + 1, slice), ring(stack + 1, slice + 1));
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
        triangles.push([south, ring(stacks - 1, slice), ring(stacks - 1, slice + 1)]);
    }
    (vertices, triangles)
}

/// An ASCII PLY file's text; `faces` may say more faces than `triangles` holds.
fn ply_text(vertices: &[[f32; 3]], triangles: &[[u32; 3]], faces: usize) -> String {
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {faces}\nproperty list uchar int vertex_indices\nend_header\n",
        vertices.len()
    );
    for v in vertices {
        writeln!(text, "{} {} {}", v[0], v[1], v[2]).unwrap();
    }
    for t in triangles {
        writeln!(text, "3 {} {} {}", t[0], t[1], t[2]).unwrap();
    }
    text
}

fn obj_text(vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> String {
    let mut text = String::new();
    for v in vertices {
        writeln!(text, "v {} {} {}", v[0], v[1], v[2]).unwrap();
    }
    for t in triangles {
        writeln!(text, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).unwrap();
    }
    text
}

/// Four overlapping spheres of different sizes, one file each (three PLY, one
/// OBJ), in `dir`; their file names in order.
fn sphere_pieces(dir: &Path) -> Vec<String> {
    let spheres = [
        ([0.0, 0.0, 0.0], 1.0, 12, 24),
        ([1.2, 0.3, -0.4], 0.8, 10, 16),
        ([-1.0, 0.6, 0.5], 0.7, 8, 20),
        ([0.3, -0.9, 0.8], 0.6, 14, 14),
    ];
    let mut names = Vec::new();
    for (i, &(centre, radius, stacks, slices)) in spheres.iter().enumerate() {
        let (vertices, triangles) = uv_sphere(centre, radius, stacks, slices);
        let (name, text) = if i == 2 {
            (format!("piece{i}.obj"), obj_text(&vertices, &triangles))
        } else {
            (
                format!("piece{i}.ply"),
                ply_text(&vertices, &triangles, triangles.len()),
            )
        };
        std::fs::write(dir.join(&name), text).unwrap();
        names.push(name);
    }
    names
}

#[test]
fn workload1_on_mesh_pieces_matches_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let pieces = sphere_pieces(dir.path());
    let pieces: Vec<&str> = pieces.iter().map(String::as_str).collect();
    workload1_on_every_rank_count(dir.path(), &pieces);
}

/// `dpp run PIPELINE SCENE… ARGS -o IMAGE`, one process or under mpirun.
fn render(
    dir: &Path,
    pipeline_file: &str,
    scene: &[&str],
    args: &[&str],
    ranks: Option<usize>,
) -> Image {
    let file = pipeline(pipeline_file);
    let image = format!(
        "{}_{}.png",
        pipeline_file.trim_end_matches(".dpp"),
        ranks.map_or("single".to_string(), |n| format!("n{n}"))
    );
    let mut all = vec!["run", &file];
    all.extend_from_slice(scene);
    all.extend_from_slice(args);
    all.extend_from_slice(&["-o", &image]);
    match ranks {
        None => single(dir, &all),
        Some(n) => mpirun(dir, n, &all),
    }
    .success();
    Image::load(&dir.join(image))
}

/// Pixels whose colour differs at all.
fn differing_pixels(a: &Image, b: &Image) -> usize {
    (a.rgb.chunks_exact(3).zip(b.rgb.chunks_exact(3)))
        .filter(|(p, q)| p != q)
        .count()
}

#[test]
fn workload2_across_ranks_matches_one_process_within_flip_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    let scenes: [&[&str]; 2] = [&["rm:40"], &[]];
    for scene in scenes {
        let name = if scene.is_empty() {
            "the built-in scene"
        } else {
            scene[0]
        };
        let args = ["--size", "96x64"];
        let reference = render(dir.path(), "workload2.dpp", scene, &args, None);
        for ranks in 2..=4 {
            let image = render(dir.path(), "workload2.dpp", scene, &args, Some(ranks));
            let error = mean_flip(&reference, &image);
            let differing = differing_pixels(&reference, &image);
            eprintln!(
                "WORKLOAD2 on {name}, {ranks} ranks: mean FLIP {error}, {differing} of {} pixels differ",
                image.pixels()
            );
            assert!(
                error <= FLIP_TOLERANCE,
                "WORKLOAD2 on {name}, {ranks} ranks: mean FLIP {error} > {FLIP_TOLERANCE}"
            );
        }
    }
}

/// WORKLOAD3 kept cheap: one sample per pixel, two AO rays.
const WORKLOAD3_ARGS: &[&str] = &["--size", "96x64", "--set", "spp=1", "--set", "aoSamples=2"];

#[test]
fn workload3_with_image_decomposition_is_the_single_process_image() {
    let dir = tempfile::tempdir().unwrap();
    let reference = render(dir.path(), "workload3.dpp", &[], WORKLOAD3_ARGS, None);
    let args = [WORKLOAD3_ARGS, &["--decompose", "image"]].concat();
    for ranks in 2..=4 {
        let image = render(dir.path(), "workload3.dpp", &[], &args, Some(ranks));
        let differing = differing_pixels(&reference, &image);
        assert_eq!(
            differing, 0,
            "WORKLOAD3 --decompose image, {ranks} ranks: {differing} pixels differ"
        );
    }
}

/// Under data decomposition a rank's shadow, AO and reflection rays see only
/// its own part of the scene, so the image differs from the single process's
/// by design: this measures by how much and asserts only that it runs.
#[test]
fn workload3_with_data_decomposition_runs_and_its_difference_is_measured() {
    let dir = tempfile::tempdir().unwrap();
    let reference = render(dir.path(), "workload3.dpp", &[], WORKLOAD3_ARGS, None);
    for ranks in [2, 4] {
        let image = render(
            dir.path(),
            "workload3.dpp",
            &[],
            WORKLOAD3_ARGS,
            Some(ranks),
        );
        let error = mean_flip(&reference, &image);
        let differing = differing_pixels(&reference, &image);
        eprintln!(
            "WORKLOAD3 --decompose data, {ranks} ranks: mean FLIP {error}, {differing} of {} pixels differ",
            image.pixels()
        );
        assert!((0.0..=1.0).contains(&error), "mean FLIP {error}");
    }
}

/// The triangles of the single process's scene, from `-v`'s `scene: … (K triangles)`.
fn single_triangle_count(dir: &Path, scene: &[&str]) -> usize {
    let w1 = pipeline("workload1.dpp");
    let mut args = vec!["run", &w1];
    args.extend_from_slice(scene);
    args.extend_from_slice(&["--size", "64x48", "-o", "count.png", "-v"]);
    let outcome = single(dir, &args).success();
    let line = (outcome.stderr.lines())
        .find(|l| l.starts_with("scene: "))
        .unwrap_or_else(|| panic!("no `scene:` line in:\n{}", outcome.stderr));
    let count = line
        .split(" (")
        .nth(1)
        .and_then(|rest| rest.split(" triangles)").next())
        .unwrap_or_else(|| panic!("no triangle count in {line:?}"));
    count.parse().unwrap_or_else(|e| panic!("{line:?}: {e}"))
}

/// Each rank's triangles, from the per-rank table `-v` prints on rank 0's stderr.
fn rank_triangle_counts(dir: &Path, scene: &[&str], ranks: usize) -> Vec<usize> {
    let w1 = pipeline("workload1.dpp");
    let mut args = vec!["run", &w1];
    args.extend_from_slice(scene);
    args.extend_from_slice(&["--size", "64x48", "-o", "count.png", "-v"]);
    let outcome = mpirun(dir, ranks, &args).success();
    let mut lines = outcome.stderr.lines();
    let header = lines
        .find(|l| l.split_whitespace().take(2).eq(["rank", "triangles"]))
        .unwrap_or_else(|| panic!("no per-rank table in:\n{}", outcome.stderr));
    let counts: Vec<usize> = lines
        .take(ranks)
        .enumerate()
        .map(|(rank, line)| {
            let words: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(
                words.first(),
                Some(&rank.to_string().as_str()),
                "{header}\n{line}"
            );
            words[1].parse().unwrap_or_else(|e| panic!("{line:?}: {e}"))
        })
        .collect();
    assert_eq!(counts.len(), ranks, "{}", outcome.stderr);
    counts
}

/// Every triangle on exactly one rank (the counts add up to the single
/// process's), and no rank holding more than `bound(total, ranks)`.
fn check_triangle_shares(dir: &Path, scene: &[&str], name: &str, bound: fn(usize, usize) -> usize) {
    let total = single_triangle_count(dir, scene);
    for ranks in 2..=4 {
        let counts = rank_triangle_counts(dir, scene, ranks);
        eprintln!("{name}, {ranks} ranks: {counts:?} of {total} triangles");
        assert_eq!(
            counts.iter().sum::<usize>(),
            total,
            "{name}, {ranks} ranks: {counts:?} do not add up to {total}"
        );
        let most = bound(total, ranks);
        assert!(
            counts.iter().all(|&c| c <= most),
            "{name}, {ranks} ranks: {counts:?}, more than {most} on a rank"
        );
    }
}

/// A volume is split into bricks balanced by cells, not by triangles, so a
/// brick may hold more than its share of the surface: each rank at most a
/// quarter of the surface above an even share.
#[test]
fn a_volume_s_triangles_are_shared_out_once_each() {
    let dir = tempfile::tempdir().unwrap();
    let bound = |total: usize, ranks: usize| total / ranks + total / 4;
    check_triangle_shares(dir.path(), &["rm:40"], "rm:40", bound);
}

/// One mesh file is split spatially by triangles (a k-d split of their
/// centres), which balances them: each rank at most an even share rounded up,
/// plus 2 for the split's rounding.
#[test]
fn one_mesh_s_triangles_are_split_evenly() {
    let dir = tempfile::tempdir().unwrap();
    let (vertices, triangles) = uv_sphere([0.0, 0.0, 0.0], 1.0, 16, 24);
    let text = ply_text(&vertices, &triangles, triangles.len());
    std::fs::write(dir.path().join("sphere.ply"), text).unwrap();
    let bound = |total: usize, ranks: usize| total.div_ceil(ranks) + 2;
    check_triangle_shares(dir.path(), &["sphere.ply"], "one mesh file", bound);
}

/// Pieces are dealt out whole, so only their count is promised.
#[test]
fn mesh_pieces_triangles_are_shared_out_once_each() {
    let dir = tempfile::tempdir().unwrap();
    let pieces = sphere_pieces(dir.path());
    let pieces: Vec<&str> = pieces.iter().map(String::as_str).collect();
    check_triangle_shares(dir.path(), &pieces, "four pieces", |total, _| total);
}

/// A failed distributed run: within the deadline, exit status 2, an error
/// that names `mentions`, and no image written.
fn check_failure(dir: &Path, outcome: Outcome, mentions: &str) {
    eprintln!(
        "{}: exit status {:?} after {:.1?}\n{}",
        outcome.what, outcome.code, outcome.elapsed, outcome.stderr
    );
    assert_eq!(
        outcome.code,
        Some(2),
        "{}: exit status {:?}, not 2:\n{}",
        outcome.what,
        outcome.code,
        outcome.stderr
    );
    assert!(
        outcome.stderr.contains("error: ") && outcome.stderr.contains(mentions),
        "{}: the error does not mention {mentions:?}:\n{}",
        outcome.what,
        outcome.stderr
    );
    assert!(
        !dir.join("out.png").exists(),
        "{}: failed but wrote out.png",
        outcome.what
    );
}

/// Three pieces of equal size, one a rank each with 3 ranks, the last
/// replaced by `broken` (named `broken_name`).
fn pieces_with_a_broken_one(dir: &Path, broken_name: &str, broken: &str) -> Vec<String> {
    let mut names = Vec::new();
    for i in 0..2 {
        let (vertices, triangles) = uv_sphere([2.5 * i as f32, 0.0, 0.0], 1.0, 6, 8);
        let name = format!("good{i}.ply");
        std::fs::write(
            dir.join(&name),
            ply_text(&vertices, &triangles, triangles.len()),
        )
        .unwrap();
        names.push(name);
    }
    std::fs::write(dir.join(broken_name), broken).unwrap();
    names.push(broken_name.to_string());
    names
}

fn run_pieces(dir: &Path, pieces: &[String]) -> Outcome {
    let w1 = pipeline("workload1.dpp");
    let mut args = vec!["run", &w1];
    args.extend(pieces.iter().map(String::as_str));
    args.extend_from_slice(&["--size", "64x48", "-o", "out.png"]);
    mpirun(dir, 3, &args)
}

/// Three pieces on three ranks, the last (rank 2's) with a valid header (read
/// by every rank to count the triangles) and a body that ends early: only the
/// rank the piece is dealt to reads the body.
fn run_with_a_truncated_piece(dir: &Path) -> Outcome {
    let (vertices, triangles) = uv_sphere([-2.5, 0.0, 0.0], 1.0, 6, 8);
    let truncated = ply_text(&vertices, &triangles[..10], triangles.len());
    let pieces = pieces_with_a_broken_one(dir, "truncated.ply", &truncated);
    run_pieces(dir, &pieces)
}

#[test]
fn a_piece_only_its_rank_finds_truncated_fails_the_whole_run() {
    let dir = tempfile::tempdir().unwrap();
    let outcome = run_with_a_truncated_piece(dir.path());
    check_failure(dir.path(), outcome, "truncated.ply");
}

#[test]

fn a_failure_on_one_rank_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let outcome = run_with_a_truncated_piece(dir.path());
    // Open MPI's own banners say "error" only in other words.
    let errors = outcome.stderr.matches("error: ").count();
    assert_eq!(errors, 1, "{} errors:\n{}", errors, outcome.stderr);
}

#[test]
fn a_piece_with_out_of_range_vertex_indices_fails_the_whole_run() {
    let dir = tempfile::tempdir().unwrap();
    let (vertices, mut triangles) = uv_sphere([-2.5, 0.0, 0.0], 1.0, 6, 8);
    triangles[5] = [0, 1, vertices.len() as u32 + 7];
    let bad = ply_text(&vertices, &triangles, triangles.len());
    let pieces = pieces_with_a_broken_one(dir.path(), "bad_index.ply", &bad);
    let outcome = run_pieces(dir.path(), &pieces);
    check_failure(dir.path(), outcome, "bad_index.ply");
}

#[test]
fn ranks_given_different_command_lines_fail_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let w1 = pipeline("workload1.dpp");
    let first = ["run", &w1, "sphere:24", "--size", "64x48", "-o", "out.png"];
    let second = ["run", &w1, "sphere:24", "--size", "64x64", "-o", "out.png"];
    let outcome = mpirun_mpmd(dir.path(), &[(1, &first), (1, &second)]);
    check_failure(dir.path(), outcome, "command line differs");
}

/// `--versus` measures two files in one process: under mpirun it is bad input.
#[test]
fn bench_versus_under_mpirun_is_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let versus = pipeline("workload2_expressions.dpp");
    #[rustfmt::skip]
    let args = [
        "bench", "sphere:24", "--size", "64x48", "--workloads", "2",
        "--versus", &versus,
    ];
    let outcome = mpirun(dir.path(), 2, &args);
    check_failure(dir.path(), outcome, "run it without mpirun");
}

/// `dpp bench` under mpirun reports every rank of every measurement: for
/// each view, workload and schedule asked for, one row per rank with its
/// triangles (which add up to the whole scene's), times, bytes and memory.
#[test]
fn bench_across_ranks_reports_every_rank_of_every_schedule() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "bench",
        "sphere:24",
        "--size",
        "64x48",
        "--views",
        "front,back",
        "--workloads",
        "1,2",
        "--warmup",
        "0",
        "--rounds",
        "1",
        "--composite",
        "direct,binary-swap",
    ];
    let outcome = mpirun(dir.path(), 3, &args).success();
    let whole = single_triangle_count(dir.path(), &["sphere:24"]);
    let tables: Vec<&str> = outcome.stdout.split("```").skip(1).step_by(2).collect();
    assert_eq!(tables.len(), 2 * 2 * 2, "{}", outcome.stdout);
    for table in tables {
        let rows: Vec<Vec<&str>> = (table.lines())
            .filter(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()))
            .map(|l| l.split_whitespace().collect())
            .collect();
        assert_eq!(rows.len(), 3, "{table}");
        let triangles: usize = rows
            .iter()
            .map(|row| row[1].parse::<usize>().unwrap())
            .sum();
        assert_eq!(triangles, whole, "{table}");
        for row in &rows {
            let run_ms: f64 = row[2].parse().unwrap();
            assert!(run_ms > 0.0, "{table}");
        }
    }
    for heading in ["front, WORKLOAD1, direct", "back, WORKLOAD2, binary-swap"] {
        assert!(
            outcome.stdout.contains(heading),
            "{heading}:\n{}",
            outcome.stdout
        );
    }
}

/// A square of side `2 * half` at depth `z`, facing +z, as OBJ text.
fn square_obj(half: f32, z: f32) -> String {
    let corners = [[-half, -half], [half, -half], [half, half], [-half, half]];
    let mut text = String::new();
    for [x, y] in corners {
        writeln!(text, "v {x} {y} {z}").unwrap();
    }
    text.push_str("f 1 2 3\nf 1 3 4\n");
    text
}

/// Translucent surfaces on two ranks are blended front to back in
/// visibility order, whichever rank holds the front one: the image is the
/// front piece's own image "over" the back piece's, pixel by pixel, bit for
/// bit (the blend does the same operations in the same order as here).
#[test]
fn translucent_pieces_blend_front_to_back_in_visibility_order() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("front.obj"), square_obj(0.5, 0.0)).unwrap();
    std::fs::write(dir.path().join("back.obj"), square_obj(1.0, -1.0)).unwrap();
    let translucent = pipeline("examples/translucent.dpp");
    // A camera, light and colour map that do not depend on the scene's bounds.
    let fixed = [
        "--eye",
        "0,0,5",
        "--look-at",
        "0,0,0",
        "--light",
        "0.3,0.6,10,1",
        "--scalar-range",
        "-2,2",
        "--set",
        "falloff=0",
        "--size",
        "32x32",
    ];
    let render = |pieces: &[&str], ranks: Option<usize>, tag: &str| -> (Vec<f32>, Vec<f32>) {
        let (color, alpha) = (format!("color={tag}-c.npy"), format!("alpha={tag}-a.npy"));
        let mut args = vec!["run", translucent.as_str()];
        args.extend_from_slice(pieces);
        args.extend_from_slice(&fixed);
        args.extend_from_slice(&["--out", &color, "--out", &alpha, "-o", "t.png"]);
        match ranks {
            None => single(dir.path(), &args).success(),
            Some(ranks) => mpirun(dir.path(), ranks, &args).success(),
        };
        let read = |name: String| read_npy::<f32>(&dir.path().join(name));
        (read(format!("{tag}-c.npy")), read(format!("{tag}-a.npy")))
    };
    let (front_color, front_alpha) = render(&["front.obj"], None, "front");
    let (back_color, back_alpha) = render(&["back.obj"], None, "back");
    let over = |color: &[f32], alpha: &[f32], back: &[f32]| -> Vec<u32> {
        (0..color.len())
            .map(|i| (color[i] + (1.0 - alpha[i]) * back[i]).to_bits())
            .collect()
    };
    let expected_color = over(&front_color, &front_alpha, &back_color);
    let expected_alpha = over(&front_alpha, &front_alpha, &back_alpha);
    // Not vacuous: both cover some pixels, and there the order matters.
    let wrong_order = over(&back_color, &back_alpha, &front_color);
    let both = (0..front_alpha.len())
        .filter(|&i| front_alpha[i] > 0.0 && back_alpha[i] > 0.0)
        .count();
    let order_matters = (0..expected_color.len())
        .filter(|&i| expected_color[i] != wrong_order[i])
        .count();
    assert!(both > 0 && order_matters > 0, "{both} {order_matters}");
    for (pieces, tag) in [
        (["front.obj", "back.obj"], "in-order"),
        (["back.obj", "front.obj"], "reversed"),
    ] {
        let (color, alpha) = render(&pieces, Some(2), tag);
        let differing = |values: &[f32], expected: &[u32]| {
            assert_eq!(values.len(), expected.len(), "{tag}");
            (values.iter().zip(expected))
                .filter(|(v, e)| v.to_bits() != **e)
                .count()
        };
        assert_eq!(
            differing(&color, &expected_color),
            0,
            "{tag}: colour components differ"
        );
        assert_eq!(
            differing(&alpha, &expected_alpha),
            0,
            "{tag}: coverage components differ"
        );
    }
}

/// VTK files: a `.pvtu`'s piece files dealt out to ranks as pieces, and a
/// `.vti` that each rank reads whole and keeps its brick of.
#[test]
fn workload1_on_vtk_files_matches_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let fixture = |name: &str| repo().join("tests/vtk").join(name).display().to_string();
    workload1_on_every_rank_count(dir.path(), &[&fixture("cells.pvtu")]);
    workload1_on_every_rank_count(dir.path(), &[&fixture("ball_zlib.vti"), "--iso", "1.5"]);
}
