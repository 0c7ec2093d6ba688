//! The `dpp` command in hostile environments rather than with hostile files:
//! a reader that closes the pipe, a folder that cannot be written, a process
//! killed while writing, absurd resources, a terminal (progress) or none, a
//! GPU run without `XDG_RUNTIME_DIR`.

use crate::common::{read_npy, text};
use std::path::Path;
use std::process::{Command, Output, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_dpp");

fn pipeline(name: &str) -> String {
    crate::common::repo()
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

fn all_text(output: &Output) -> String {
    format!("{}{}", text(&output.stdout), text(&output.stderr))
}

/// The files in `dir` whose names start with `.dpp-` (temporary outputs).
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with(".dpp-"))
        .collect()
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

/// `dpp ARGS` in `dir` whose stdout's reader goes away before the first
/// message (`dpp … | head -0`).
fn run_with_stdout_closed(args: &[String], dir: &Path) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    child.wait_with_output().unwrap()
}

#[test]
fn a_closed_stdout_ends_the_messages_not_the_run() {
    let dir = scene_dir();
    let output = run_with_stdout_closed(&workload1_args(), dir.path());
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
        let output = run_with_stdout_closed(&args, dir.path());
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

#[test]
fn an_output_that_cannot_be_written_is_a_clear_error() {
    let dir = scene_dir();
    std::fs::write(dir.path().join("a-file"), "").unwrap();
    for (target, reason) in [
        ("missing/depth.npy", "the folder `missing` does not exist"),
        ("a-file/depth.npy", "cannot write a-file/depth.npy"),
        ("missing/image.png", "the folder `missing` does not exist"),
    ] {
        let mut args = workload1_args();
        args.truncate(args.len() - 6);
        let name = Path::new(target).file_stem().unwrap().to_str().unwrap();
        args.extend(["--out".into(), format!("{name}={target}")]);
        let output = Command::new(BIN)
            .args(&args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let all = all_text(&output);
        assert_eq!(output.status.code(), Some(1), "{target}: {all}");
        assert!(all.contains(&format!("cannot write {target}")), "{all}");
        assert!(all.contains(reason), "{target}: {all}");
        assert!(!all.contains("panicked"), "{all}");
        assert!(!dir.path().join("missing").exists());
    }

    // A folder without write permission (as root, permissions do not stop a
    // write, so there is nothing to see).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let locked = dir.path().join("locked");
        std::fs::create_dir(&locked).unwrap();
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o555)).unwrap();
        if std::fs::write(locked.join("probe"), "").is_err() {
            let mut args = workload1_args();
            args.truncate(args.len() - 6);
            args.extend(["--out".into(), "depth=locked/depth.npy".into()]);
            let output = Command::new(BIN)
                .args(&args)
                .current_dir(dir.path())
                .output()
                .unwrap();
            let all = all_text(&output);
            assert_eq!(output.status.code(), Some(1), "{all}");
            assert!(all.contains("cannot write locked/depth.npy"), "{all}");
            assert_eq!(std::fs::read_dir(&locked).unwrap().count(), 0);
        }
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
}

/// A write cut short (a file size limit stands in for a full disk, and its
/// signal for a kill in the middle of the write) never leaves a truncated file
/// under the output's name: a file written before stays as it was.
#[cfg(unix)]
#[test]
fn an_interrupted_write_leaves_no_partial_file() {
    let dir = scene_dir();
    let mut args = workload1_args();
    args.truncate(args.len() - 6);
    args.extend(["--out".into(), "depth=depth.npy".into()]);
    // `ulimit -f 4`: writes past 2 KiB fail (the depth array is 3 KiB).
    let limited = |trap: &str| {
        Command::new("sh")
            .arg("-c")
            .arg(format!("{trap} ulimit -f 4; exec \"$0\" \"$@\""))
            .arg(BIN)
            .args(&args)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };

    // The write fails (EFBIG, as ENOSPC would): a clear error naming the file,
    // the old file untouched, no temporary file left.
    std::fs::write(dir.path().join("depth.npy"), "the previous run's").unwrap();
    let output = limited("trap '' XFSZ;");
    let all = all_text(&output);
    assert_eq!(output.status.code(), Some(1), "{all}");
    assert!(all.contains("cannot write depth.npy"), "{all}");
    assert_eq!(
        std::fs::read_to_string(dir.path().join("depth.npy")).unwrap(),
        "the previous run's"
    );
    assert!(
        temporaries(dir.path()).is_empty(),
        "{:?}",
        temporaries(dir.path())
    );

    // The process is killed in the middle of the write (SIGXFSZ): nothing
    // under the output's name.
    std::fs::remove_file(dir.path().join("depth.npy")).unwrap();
    let output = limited("");
    assert!(!output.status.success(), "{}", all_text(&output));
    assert!(!dir.path().join("depth.npy").exists());
}

/// A pipeline that reads `volume.*` run without a volume is a usage error
/// that says what to give, found before any work; with one it runs on it.
#[test]
fn a_volume_pipeline_without_a_volume_says_what_to_give() {
    let dir = scene_dir();
    let iso = pipeline("isosurface.dpp");
    for args in [vec!["run", &iso], vec!["run", &iso, "quad.obj"]] {
        let output = Command::new(BIN)
            .args(&args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let all = all_text(&output);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {all}");
        assert!(all.contains("reads `volume.cells`"), "{all}");
        assert!(all.contains("pass a volume"), "{all}");
        assert!(all.contains(".nii.gz") && all.contains("--raw"), "{all}");
    }

    let gen = Command::new(BIN)
        .args(["gen", "sphere", "--grid", "12,12,12", "-o", "ball.nii.gz"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(gen.status.success(), "{}", all_text(&gen));
    // The level is the pipeline's own param; --iso belongs to traced volumes.
    let output = Command::new(BIN)
        .args(["run", &iso, "ball.nii.gz", "--iso", "0"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2), "{}", all_text(&output));
    assert!(all_text(&output).contains("--set NAME=VALUE"));
    let output = Command::new(BIN)
        .args(["run", &iso, "ball.nii.gz", "--set", "level=0.5"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(0), "{}", all_text(&output));
    let count = text(&output.stdout);
    let count: u64 = count
        .trim()
        .strip_prefix("count = ")
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{count}"));
    assert!(count > 100, "{count} triangles");
}

/// The volume renderer without a volume, or with a transfer function it
/// cannot read, is a usage error that names what is wrong; with a volume it
/// renders it.
#[test]
fn volume_rendering_says_what_is_wrong_with_its_input() {
    let dir = scene_dir();
    let volume = pipeline("volume.dpp");
    let run = |args: &[&str]| {
        let output = Command::new(BIN)
            .arg("run")
            .arg(&volume)
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        (output.status.code(), all_text(&output))
    };
    for args in [&[][..], &["quad.obj"][..]] {
        let (code, all) = run(args);
        assert_eq!(code, Some(2), "{args:?}: {all}");
        assert!(all.contains("give one volume as the scene"), "{all}");
    }
    std::fs::write(dir.path().join("bad.json"), r#"{"RGBPoints": [0, 0, 0]}"#).unwrap();
    for (transfer, expected) in [
        ("bad.json", "RGBPoints"),
        ("missing.json", "cannot read the colour-map preset"),
        ("viridiss", "did you mean `viridis`"),
    ] {
        let (code, all) = run(&["sphere:12", "--size", "16x12", "--transfer", transfer]);
        assert_eq!(code, Some(2), "{transfer}: {all}");
        assert!(all.contains(expected), "{transfer}: {all}");
    }
    // The renderer reads the volume itself: no isosurface level.
    let (code, all) = run(&["sphere:12", "--size", "16x12", "--iso", "0"]);
    assert_eq!(code, Some(2), "{all}");
    assert!(all.contains("--iso is for pipelines that trace"), "{all}");
    let (code, all) = run(&[
        "sphere:12",
        "--size",
        "16x12",
        "--transfer",
        "grey",
        "-o",
        "v.png",
    ]);
    assert_eq!(code, Some(0), "{all}");
    assert!(dir.path().join("v.png").is_file());
}

/// Runs `dpp args` in `dir` and waits at most `seconds` for it (then kills it
/// and fails): an absurd resource must get a quick answer, not a long wait.
fn dpp_within(seconds: u64, args: &[&str], dir: &Path) -> (Option<i32>, String) {
    let log = dir.join(".log");
    // One open file for both streams, so that they share its offset.
    let file = std::fs::File::create(&log).unwrap();
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .stdout(file.try_clone().unwrap())
        .stderr(file)
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(seconds);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if std::time::Instant::now() > deadline {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!(
                "dpp {args:?} ran for more than {seconds} s:\n{}",
                std::fs::read_to_string(&log).unwrap()
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let all = std::fs::read_to_string(&log).unwrap();
    assert!(!all.contains("panicked"), "dpp {args:?}: {all}");
    (status.code(), all)
}

/// Absurd resources get a clear answer at once (the bound leaves room for a
/// busy machine; the answers take milliseconds).
#[test]
fn absurd_resources_are_answered_at_once() {
    let dir = scene_dir();
    let (w1, w3) = (pipeline("workload1.dpp"), pipeline("workload3.dpp"));
    // Far more threads than cores: capped with a warning, and the run is quick.
    let (status, all) = dpp_within(
        20,
        &[
            "run",
            &w1,
            "quad.obj",
            "--size",
            "64x64",
            "--threads",
            "10000",
        ],
        dir.path(),
    );
    assert_eq!(status, Some(0), "{all}");
    assert!(
        all.contains("warning: --threads 10000 is more than"),
        "{all}"
    );

    // An image larger than a camera may be: refused with the arguments.
    let (status, all) = dpp_within(20, &["run", &w1, "--size", "100000x100000"], dir.path());
    assert_eq!(status, Some(2), "{all}");
    assert!(all.contains("more than the 268435456"), "{all}");

    // A loop bound from a param: refused before the loop's first iteration.
    let (status, all) = dpp_within(
        20,
        &[
            "run",
            &w3,
            "quad.obj",
            "--size",
            "16x16",
            "--set",
            "maxDepth=1000000000",
            "--set",
            "compactOn=false",
        ],
        dir.path(),
    );
    assert_eq!(status, Some(1), "{all}");
    assert!(all.contains("`for rayDepth in 0..1000000000`"), "{all}");

    // Bench rounds beyond reason (and beyond u32 once summed).
    for option in ["--rounds", "--warmup"] {
        let (status, all) = dpp_within(20, &["bench", option, "4000000000"], dir.path());
        assert_eq!(status, Some(2), "{all}");
        assert!(
            all.contains(&format!("{option} 4000000000: at most")),
            "{all}"
        );
    }
}

/// Runs `dpp args` in `dir` with stderr on a pseudo-terminal (100 columns)
/// and stdout on a pipe: its exit status, stdout, and what the terminal got.
#[cfg(target_os = "linux")]
fn dpp_on_a_terminal(args: &[&str], dir: &Path) -> (Option<i32>, String, String) {
    use std::io::Read;
    use std::os::fd::{FromRawFd, OwnedFd};
    use std::os::unix::fs::OpenOptionsExt;
    // SAFETY: plain libc calls on a descriptor this function owns; every
    // result is checked, and the descriptor is handed to an OwnedFd at once.
    let (master, slave_path) = unsafe {
        let master = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY);
        assert!(master >= 0, "posix_openpt");
        let master = OwnedFd::from_raw_fd(master);
        let fd = std::os::fd::AsRawFd::as_raw_fd(&master);
        assert_eq!(libc::grantpt(fd), 0, "grantpt");
        assert_eq!(libc::unlockpt(fd), 0, "unlockpt");
        let size = libc::winsize {
            ws_row: 30,
            ws_col: 100,
            ws_xpixel: 0,
            ws_ypixel: 0,
        };
        assert_eq!(libc::ioctl(fd, libc::TIOCSWINSZ, &size), 0, "TIOCSWINSZ");
        let mut name = [0 as libc::c_char; 128];
        assert_eq!(libc::ptsname_r(fd, name.as_mut_ptr(), name.len()), 0);
        let path = std::ffi::CStr::from_ptr(name.as_ptr())
            .to_str()
            .unwrap()
            .to_owned();
        (std::fs::File::from(master), path)
    };
    let child = {
        let slave = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOCTTY)
            .open(&slave_path)
            .unwrap();
        // The command (and its copy of the terminal) is gone after the spawn,
        // so the reader sees the end once the child has exited.
        Command::new(BIN)
            .args(args)
            .current_dir(dir)
            .env("TERM", "xterm")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(slave)
            .spawn()
            .unwrap()
    };
    let reader = std::thread::spawn(move || {
        let mut master = master;
        let mut seen = Vec::new();
        let mut buffer = [0u8; 4096];
        // Linux answers EIO once no process holds the terminal any more.
        while let Ok(n @ 1..) = master.read(&mut buffer) {
            seen.extend_from_slice(&buffer[..n]);
        }
        seen
    });
    let output = child.wait_with_output().unwrap();
    let terminal = reader.join().unwrap();
    (output.status.code(), text(&output.stdout), text(&terminal))
}

/// On a terminal `dpp run` shows a line per phase of its work; not on a pipe,
/// and not with --quiet.
#[cfg(target_os = "linux")]
#[test]
fn progress_lines_on_a_terminal_only() {
    let dir = scene_dir();
    let w1 = pipeline("workload1.dpp");
    let args = ["run", &w1, "quad.obj", "--size", "32x24", "-o", "image.png"];
    let phases = [
        "loading quad.obj: ",
        "vertex normals of 2 triangles: ",
        "BVH over 2 triangles: ",
        "running workload1: ",
        "writing image.png: ",
    ];

    let (status, stdout, terminal) = dpp_on_a_terminal(&args, dir.path());
    assert_eq!(status, Some(0), "{terminal}");
    assert_eq!(stdout, "wrote image to image.png\n");
    for phase in phases {
        assert!(terminal.contains(phase), "no `{phase}` in {terminal:?}");
    }

    let quiet: Vec<&str> = args.iter().copied().chain(["--quiet"]).collect();
    let (status, stdout, terminal) = dpp_on_a_terminal(&quiet, dir.path());
    assert_eq!(status, Some(0), "{terminal}");
    assert_eq!(stdout, "wrote image to image.png\n");
    assert_eq!(terminal, "", "--quiet");

    let output = Command::new(BIN)
        .args(args)
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(0));
    assert_eq!(text(&output.stderr), "", "stderr is not a terminal");
}

/// A GPU run in a headless session (no `XDG_RUNTIME_DIR`, no display, as
/// over ssh or in a container) prints nothing from the Vulkan stack: Mesa's
/// device-selection layer used to report twice that it could not reach a
/// Wayland display.
#[test]
fn a_headless_gpu_run_prints_no_driver_noise() {
    if !crate::common::gpu_available("the headless GPU run") {
        return;
    }
    let dir = scene_dir();
    let w1 = pipeline("workload1.dpp");
    let mut command = Command::new(BIN);
    command
        .args([
            "run",
            &w1,
            "quad.obj",
            "--size",
            "16x16",
            "--backend",
            "gpu",
        ])
        .args(["-o", "gpu.png"])
        .current_dir(dir.path());
    for name in [
        "XDG_RUNTIME_DIR",
        "WAYLAND_DISPLAY",
        "WAYLAND_SOCKET",
        "DISPLAY",
        "NODEVICE_SELECT",
        "MESA_VK_DEVICE_SELECT",
        "DRI_PRIME",
    ] {
        command.env_remove(name);
    }
    let output = command.output().unwrap();
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stderr}");
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    assert_eq!(stderr, "", "nothing but the image on a quiet run");
    assert!(dir.path().join("gpu.png").exists());
}
