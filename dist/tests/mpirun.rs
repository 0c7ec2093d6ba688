//! The executor under a real `mpirun`: the plans are verified in memory by
//! the unit tests, but only real ranks show that the messages match, that
//! nothing deadlocks, and that a failure on one rank reaches every rank.
//!
//! The outer test re-launches this test binary under `mpirun -n N` with
//! `DPP_DIST_MPI_CHILD` set and `--exact` the name of an inner test; inner
//! tests do nothing without that variable. Every rank can compute every
//! other rank's fragments (they are functions of rank and pixel), so rank 0
//! checks its image against the left fold it expects, and a mismatch fails
//! the child, which fails `mpirun`. A hang is a failure too: every `mpirun`
//! runs under `timeout`.
#![cfg(feature = "mpi")]

use dpp_dist::{composite, gather_pieces, CompositeSchedule, Ranks};
use dpp_runtime::interpret::RunError;
use dpp_runtime::{Column, ElemType, ErrorKind, RecordRegistry, RecordType};
use glam::Vec3;
use std::process::Command;
use std::sync::Arc;

const CHILD: &str = "DPP_DIST_MPI_CHILD";

/// What a child prints, with its rank, when its test ran to the end.
const FINISHED: &str = "mpirun child finished on rank";

/// One line in one write, so that other ranks' output cannot split it.
fn finished(rank: usize) {
    println!("{FINISHED} {rank}");
}

fn in_child() -> bool {
    std::env::var_os(CHILD).is_some()
}

/// Runs inner test `test` on `ranks` ranks; panics unless every rank passes.
fn mpirun(ranks: usize, test: &str) {
    let exe = std::env::current_exe().unwrap();
    let output = Command::new("timeout")
        .args(["--kill-after=5", "60", "mpirun", "--oversubscribe"])
        // Containers often forbid the cross-memory attach of shared memory.
        .args(["--mca", "btl_vader_single_copy_mechanism", "none"])
        .args(["-x", CHILD, "-n", &ranks.to_string()])
        .arg(&exe)
        .args(["--exact", test, "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .output()
        .expect("mpirun (Open MPI) and timeout (coreutils) on the PATH");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "{test} on {ranks} ranks: {} (124: timed out)\n--- stdout\n{stdout}\n--- stderr\n{stderr}",
        output.status
    );
    // Every rank's own line: the test ran to its end there, not filtered
    // away. (The harness's summary cannot be counted: the ranks' output
    // interleaves mid-line.)
    let finished: std::collections::BTreeSet<&str> = (stdout.lines())
        .filter_map(|line| line.split(FINISHED).nth(1))
        .map(str::trim)
        .collect();
    assert_eq!(
        finished.len(),
        ranks,
        "{test} on {ranks} ranks did not run everywhere:\n{stdout}"
    );
}

#[test]
fn under_mpirun() {
    if in_child() {
        return;
    }
    for ranks in [1, 2, 3, 4, 5, 6] {
        mpirun(ranks, "child_composite");
    }
    for ranks in [1, 2, 3, 4] {
        mpirun(ranks, "child_agree");
    }
}

fn schedules() -> Vec<CompositeSchedule> {
    ["direct", "binary-swap", "radix-k", "radix-k:2", "radix-k:3"]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect()
}

/// A 2×2 matrix of wrapping u32s per pixel, as a record: products are
/// associative but not commutative, so any blend out of order shows.
fn matrix_of(rank: usize, pixel: usize) -> [u32; 4] {
    let (r, i) = (rank as u32, pixel as u32);
    [r + 1, i % 7 + r * 3, (i * 5 + r) % 11, 2 * r + i % 3 + 1]
}

fn multiply(a: [u32; 4], b: [u32; 4]) -> [u32; 4] {
    let m = |x: u32, y: u32| x.wrapping_mul(y);
    [
        m(a[0], b[0]).wrapping_add(m(a[1], b[2])),
        m(a[0], b[1]).wrapping_add(m(a[1], b[3])),
        m(a[2], b[0]).wrapping_add(m(a[3], b[2])),
        m(a[2], b[1]).wrapping_add(m(a[3], b[3])),
    ]
}

fn depth_of(rank: usize, pixel: usize) -> f32 {
    ((pixel * 7 + rank * 3) % 5) as f32
}

/// Rank `rank`'s fragments: a matrix record, a depth, an id and a colour.
fn fragments(rank: usize, n: usize, matrix: dpp_runtime::RecordId) -> Vec<Arc<Column>> {
    let field = |k: usize| Arc::new(Column::U32((0..n).map(|i| matrix_of(rank, i)[k]).collect()));
    vec![
        Arc::new(Column::Record {
            ty: matrix,
            fields: (0..4).map(field).collect(),
        }),
        Arc::new(Column::F32((0..n).map(|i| depth_of(rank, i)).collect())),
        Arc::new(Column::U32(vec![rank as u32; n])),
        Arc::new(Column::Vec3(
            (0..n)
                .map(|i| Vec3::new(rank as f32, i as f32, 1.0))
                .collect(),
        )),
    ]
}

/// Matrices multiply; depth and id go to the nearer (front on ties);
/// colours go with the id.
fn blend(front: &[Arc<Column>], back: &[Arc<Column>]) -> Result<Vec<Arc<Column>>, RunError> {
    let n = front[1].len();
    let matrix = |cols: &[Arc<Column>], i: usize| -> [u32; 4] {
        std::array::from_fn(|k| cols[0].field(k).unwrap().view().as_u32()[i])
    };
    let products: Vec<[u32; 4]> = (0..n)
        .map(|i| multiply(matrix(front, i), matrix(back, i)))
        .collect();
    let Column::Record { ty, .. } = front[0].as_ref() else {
        panic!("the matrix is a record")
    };
    let (fd, bd) = (front[1].view().as_f32(), back[1].view().as_f32());
    let nearer: Vec<bool> = (0..n).map(|i| fd[i] <= bd[i]).collect();
    let pick = |k: usize| -> Arc<Column> {
        let (f, b) = (front[k].view(), back[k].view());
        Arc::new(match (f, b) {
            (dpp_runtime::ColumnView::F32(f), dpp_runtime::ColumnView::F32(b)) => Column::F32(
                (0..n)
                    .map(|i| if nearer[i] { f[i] } else { b[i] })
                    .collect(),
            ),
            (dpp_runtime::ColumnView::U32(f), dpp_runtime::ColumnView::U32(b)) => Column::U32(
                (0..n)
                    .map(|i| if nearer[i] { f[i] } else { b[i] })
                    .collect(),
            ),
            (dpp_runtime::ColumnView::Vec3(f), dpp_runtime::ColumnView::Vec3(b)) => Column::Vec3(
                (0..n)
                    .map(|i| if nearer[i] { f[i] } else { b[i] })
                    .collect(),
            ),
            _ => panic!("unexpected column types"),
        })
    };
    Ok(vec![
        Arc::new(Column::Record {
            ty: *ty,
            fields: (0..4)
                .map(|k| Arc::new(Column::U32(products.iter().map(|m| m[k]).collect())))
                .collect(),
        }),
        pick(1),
        pick(2),
        pick(3),
    ])
}

fn registry() -> (RecordRegistry, dpp_runtime::RecordId) {
    let mut records = RecordRegistry::default();
    let id = records.register(RecordType {
        name: "Matrix".into(),
        fields: ["a", "b", "c", "d"]
            .iter()
            .map(|f| (f.to_string(), ElemType::U32))
            .collect(),
        doc: String::new(),
    });
    (records, id)
}

#[test]
fn child_composite() {
    if !in_child() {
        return;
    }
    let ranks = Ranks::init().unwrap();
    let (p, me) = (ranks.size(), ranks.rank());
    let (records, matrix) = registry();
    let orders: Vec<Vec<usize>> = vec![
        (0..p).collect(),
        (0..p).rev().collect(),
        (0..p).map(|i| (i * 2 + 1) % p).collect::<Vec<_>>(),
    ];
    for n in [0, 1, 5, 1003] {
        for schedule in schedules() {
            for order in &orders {
                let mut seen = vec![false; p];
                if !order
                    .iter()
                    .all(|&r| !std::mem::replace(&mut seen[r], true))
                {
                    continue; // (i * 2 + 1) % p is a permutation for odd p only
                }
                let mut calls = 0;
                let mut counting = |f: &[Arc<Column>], b: &[Arc<Column>]| {
                    calls += 1;
                    blend(f, b)
                };
                let out = composite(
                    &ranks,
                    &schedule,
                    fragments(me, n, matrix),
                    order,
                    &records,
                    &mut counting,
                )
                .unwrap();
                if p == 1 {
                    assert_eq!(calls, 0, "one rank never blends");
                }
                let Some(image) = out.image else {
                    assert_ne!(me, 0, "rank 0 holds the image");
                    continue;
                };
                assert_eq!(me, 0, "only rank 0 holds the image");
                assert_eq!(
                    out.stats.rounds.len(),
                    schedule_rounds(&schedule, p, n, order)
                );
                for i in 0..n {
                    let what = format!("{schedule} p={p} n={n} order={order:?} pixel {i}");
                    let product = order[1..]
                        .iter()
                        .fold(matrix_of(order[0], i), |m, &r| multiply(m, matrix_of(r, i)));
                    let got: [u32; 4] =
                        std::array::from_fn(|k| image[0].field(k).unwrap().view().as_u32()[i]);
                    assert_eq!(got, product, "{what}: matrix");
                    let front = order
                        .iter()
                        .copied()
                        .reduce(|a, b| {
                            if depth_of(a, i) <= depth_of(b, i) {
                                a
                            } else {
                                b
                            }
                        })
                        .unwrap();
                    assert_eq!(
                        image[1].view().as_f32()[i],
                        depth_of(front, i),
                        "{what}: depth"
                    );
                    assert_eq!(image[2].view().as_u32()[i], front as u32, "{what}: id");
                    assert_eq!(
                        image[3].view().as_vec3()[i].x,
                        front as f32,
                        "{what}: colour"
                    );
                }
                assert!(image.iter().all(|c| c.len() == n));
            }
        }
    }
    // Image decomposition: rank r is right only about the pixels it owns.
    let owner = |i: usize| (i / 3) % p;
    let n = 100;
    let mine: Vec<Arc<Column>> = vec![
        Arc::new(Column::U32(
            (0..n as u32)
                .map(|i| if owner(i as usize) == me { i * 10 } else { 7 })
                .collect(),
        )),
        Arc::new(Column::Bool(
            (0..n).map(|i| owner(i) == me && i % 2 == 0).collect(),
        )),
    ];
    let image = gather_pieces(&ranks, mine, &owner, &records).unwrap();
    if me == 0 {
        let image = image.expect("rank 0 assembles the image");
        assert_eq!(
            *image[0],
            Column::U32((0..n as u32).map(|i| i * 10).collect())
        );
        assert_eq!(
            *image[1],
            Column::Bool((0..n).map(|i| i % 2 == 0).collect())
        );
    } else {
        assert!(image.is_none());
    }
    finished(me);
}

fn schedule_rounds(schedule: &CompositeSchedule, p: usize, n: usize, order: &[usize]) -> usize {
    if p == 1 {
        0
    } else {
        dpp_dist::plan(schedule, p, n, order).rounds.len()
    }
}

#[test]
fn child_agree() {
    if !in_child() {
        return;
    }
    let ranks = Ranks::init().unwrap();
    let (p, me) = (ranks.size(), ranks.rank());

    // The collectives.
    let mut low = [me as f32, -(me as f32)];
    ranks.all_min_f32(&mut low);
    assert_eq!(low, [0.0, -((p - 1) as f32)]);
    let mut high = [me as f32];
    ranks.all_max_f32(&mut high);
    assert_eq!(high, [(p - 1) as f32]);
    assert_eq!(ranks.all_sum_u64(me as u64 + 1), (p * (p + 1) / 2) as u64);
    assert_eq!(
        ranks.exclusive_sum_u64(me as u64 + 1),
        (me * (me + 1) / 2) as u64
    );
    let gathered = ranks.all_gather_bytes(&vec![me as u8; me]);
    assert_eq!(
        gathered,
        (0..p).map(|r| vec![r as u8; r]).collect::<Vec<_>>()
    );
    let mut bytes = if me == p - 1 {
        b"from the last".to_vec()
    } else {
        Vec::new()
    };
    ranks.broadcast_bytes(p - 1, &mut bytes);
    assert_eq!(bytes, b"from the last");
    ranks.barrier();

    // Everyone fine: everyone Ok.
    assert_eq!(ranks.agree(Ok::<_, RunError>(me)), Ok(me));
    // Ranks 1 and p-1 fail: the lowest failing rank's error reaches the others.
    if p > 1 {
        let mine = match me {
            1 => Err(RunError::bad_input("rank one cannot read its piece")),
            r if r == p - 1 => Err(RunError::resource_limit("out of memory")),
            _ => Ok(()),
        };
        let agreed = ranks.agree(mine.clone());
        match mine {
            Err(own) => assert_eq!(agreed, Err(own), "a failing rank keeps its error"),
            Ok(()) => assert_eq!(
                agreed,
                Err(RunError::bad_input(
                    "rank 1: rank one cannot read its piece"
                ))
            ),
        }
    }

    // The same command line everywhere, then not.
    assert_eq!(
        ranks.same_on_every_rank("the command line", b"dpp run a.dpp"),
        Ok(())
    );
    let line = if me == p - 1 && p > 1 {
        "dpp run b.dpp"
    } else {
        "dpp run a.dpp"
    };
    let same = ranks.same_on_every_rank("the command line", line.as_bytes());
    if p > 1 {
        let error = same.unwrap_err();
        assert_eq!(error.kind, ErrorKind::BadInput);
        assert!(
            error.message.contains(&format!("rank {}", p - 1)),
            "{}",
            error.message
        );
    }

    // A blend that fails on the last rank (which takes part in every
    // schedule's rounds, the fold's too) mid-schedule: every rank returns
    // an error, none hangs, and the ranks can still talk afterwards.
    let (records, matrix) = registry();
    for schedule in schedules() {
        let order: Vec<usize> = (0..p).collect();
        let mut failing = |f: &[Arc<Column>], b: &[Arc<Column>]| {
            if me == p - 1 {
                Err(RunError::internal("the blend broke"))
            } else {
                blend(f, b)
            }
        };
        let out = composite(
            &ranks,
            &schedule,
            fragments(me, 64, matrix),
            &order,
            &records,
            &mut failing,
        );
        if p > 1 {
            let error = out.expect_err("a failed blend fails every rank");
            let expected = if me == p - 1 {
                "the blend broke".to_string()
            } else {
                format!("rank {}: the blend broke", p - 1)
            };
            assert_eq!(error, RunError::internal(expected), "{schedule}");
        }
    }
    assert_eq!(ranks.all_sum_u64(1), p as u64);
    finished(me);
}
