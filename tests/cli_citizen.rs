//! The `dpp` command in hostile environments rather than with hostile files:
//! a reader that closes the pipe, a folder that cannot be written, a process
//! killed while writing, absurd resources, a terminal (progress) or none, a
//! GPU run without `XDG_RUNTIME_DIR`.

mod common;

use common::text;
use std::path::Path;
use std::process::{Command, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_dpp");

fn pipeline(name: &str) -> String {
    common::repo()
        .join("pipelines")
        .join(name)
        .display()
        .to_string()
}

/// A quad seen from the front: a tiny scene that loads at once.
const QUAD: &str = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n";

/// A folder holding `quad.obj`.
fn scene_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("quad.obj"), QUAD).unwrap();
    dir
}

fn read_npy<T: npyz::Deserialize>(path: &Path) -> Vec<T> {
    let bytes = std::fs::read(path).unwrap();
    npyz::NpyFile::new(&bytes[..]).unwrap().into_vec().unwrap()
}

/// WORKLOAD1 on the quad, writing `image.png`, `depth.npy` and `prim.npy`:
/// three `wrote …` lines on stdout.
fn workload1_args() -> Vec<String> {
    [
        "run",
        &pipeline("workload1.dpp"),
        "quad.obj",
        "--size",
        "32x24",
        "--threads",
        "1",
        "--out",
        "depth=depth.npy",
        "--out",
        "prim=prim.npy",
        "-o",
        "image.png",
    ]
    .map(String::from)
    .to_vec()
}

#[test]
fn a_closed_stdout_ends_the_messages_not_the_run() {
    let dir = scene_dir();
    let mut child = Command::new(BIN)
        .args(workload1_args())
        .current_dir(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The reader goes away before the first message (`dpp run … | head -0`).
    drop(child.stdout.take());
    let output = child.wait_with_output().unwrap();
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stderr}");
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "{stderr}"
    );
    assert!(stderr.is_empty(), "nothing to say on stderr: {stderr}");
    // Every output was written, and written whole.
    assert_eq!(
        read_npy::<f32>(&dir.path().join("depth.npy")).len(),
        32 * 24
    );
    assert_eq!(read_npy::<u32>(&dir.path().join("prim.npy")).len(), 32 * 24);
    let image = image::open(dir.path().join("image.png")).unwrap();
    assert_eq!((image.width(), image.height()), (32, 24));

    // The same for the commands that print a lot.
    for args in [
        vec!["plan".to_string(), pipeline("workload3.dpp")],
        vec!["functors".to_string()],
    ] {
        let mut child = Command::new(BIN)
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let output = child.wait_with_output().unwrap();
        let stderr = text(&output.stderr);
        assert_eq!(output.status.code(), Some(0), "dpp {args:?}: {stderr}");
        assert!(stderr.is_empty(), "dpp {args:?}: {stderr}");
    }
}

/// stdout on a full disk is not a closed pipe: the outputs are still written,
/// and the command fails once they are.
#[cfg(target_os = "linux")]
#[test]
fn a_full_stdout_fails_after_the_outputs() {
    let dir = scene_dir();
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let output = Command::new(BIN)
        .args(workload1_args())
        .current_dir(dir.path())
        .stdout(Stdio::from(full))
        .output()
        .unwrap();
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("cannot write to stdout"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for name in ["depth.npy", "prim.npy", "image.png"] {
        assert!(dir.path().join(name).exists(), "{name} was not written");
    }
}
