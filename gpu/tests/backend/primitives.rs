//! Every primitive form of docs/language.md §3, run through the whole stack (pipeline text
//! → plan → CPU backend) on random inputs, against plain sequential
//! references; fused and unfused, on 1 and 2 threads, must agree bit for bit.

use dpp_gpu::{run_plan_gpu, GpuContext, GpuLimits, GpuRunContext};
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::{OutputValue, RunResult};
use dpp_runtime::*;
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

fn library() -> FunctorLibrary {
    let mut library = crate::common::library();
    for (name, ty) in [
        ("u32Data", ElemType::U32),
        ("f32Data", ElemType::F32),
        ("boolData", ElemType::Bool),
        ("i32Data", ElemType::I32),
    ] {
        crate::data::register_data_functor(&mut library, name, ty);
    }
    // Values of `sortByKey` that are records: every field moves with its key.
    let pair = library.records.register(RecordType {
        name: "Pair".into(),
        fields: vec![
            ("id".into(), ElemType::U32),
            ("weight".into(), ElemType::F32),
        ],
        doc: "a test record".into(),
    });
    crate::data::register_data_functor(&mut library, "pairData", ElemType::Record(pair));
    library
}

const PIPELINE: &str = r#"
param n = 0
param m = 1
param k = 1
pipeline primitives {
    a       = iota(n) → map<u32Data>(column: 0)
    b       = iota(n) → map<u32Data>(column: 1)
    idx     = iota(n) → map<u32Data>(column: 2)
    perm    = iota(n) → map<u32Data>(column: 3)
    keep    = iota(n) → map<boolData>(column: 4)
    dst     = iota(m) → map<u32Data>(column: 5)
    f       = iota(n) → map<f32Data>(column: 6)
    flags   = iota(n) → map<boolData>(column: 7)
    grouped = iota(n * k) → map<u32Data>(column: 8)
    src     = iota(m) → map<u32Data>(column: 9)
    out added       = map<add>(a, b)
    out gathered    = gather(idx, src)
    out groupSums   = gather<sum>(grouped, group: k)
    // Nested stages (docs/language.md §6, rule 5): pair `j` of element
    // `j / k`, its terms summed per element in the stage that makes them,
    // read at the inner index (`grouped`) and through an index (`a`); and a
    // fan-out's copies, each with its lane, folded the same way.
    pair        = iota(n * k)
    out pairSums    = gather<sum>(map<mul>(gather(pair / k, a), grouped), group: k)
    out laneSums    = gather<sum>(map<add>(scatter<lane>(b, fanout: k), scatter<repeat>(b, fanout: k)), group: k)
    out permuted    = scatter(perm, a, len: n)
    out masked      = scatter(perm, a, mask: keep, len: n)
    out overwritten = scatter(idx, a, into: dst)
    out combined    = scatter<add>(idx, a, into: dst)
    // A loop's scatters that rebind their own targets (the CPU backend moves
    // such a target instead of copying it): one whose old value a gather of
    // the same stage still reads, one whose old value nothing else reads.
    acc     = iota(m) → map<u32Data>(column: 5)
    seen    = fill(n, 0)
    own     = iota(m) → map<u32Data>(column: 5)
    for round in 0..2 {
        seen = gather(idx, acc)
        acc  = scatter(idx, a, into: acc)
        own  = scatter<add>(idx, b, into: own)
    }
    out accSeen = seen
    out accOverwritten = acc
    out ownTwice = own
    out repeated    = scatter<repeat>(a, fanout: k)
    out lanes       = scatter<lane>(a, fanout: k)
    out total       = reduce<add>(a)
    out smallest    = reduce<min>(a)
    out fsum        = reduce<add>(f)
    out inclusive   = scan<add>(a)
    out exclusive   = exclusiveScan<add>(a)
    out segmentedInclusive = scan<add>(a, segments: flags)
    out segmentedExclusive = exclusiveScan<max>(a, segments: flags)
    out fscan       = scan<add>(f)
    fk      = iota(n) → map<f32Data>(column: 10)
    ik      = iota(n) → map<i32Data>(column: 11)
    pairs   = iota(n) → map<pairData>(column: 12)
    out sortedA     = sort(a)
    out sortedSums  = sort(map<add>(a, b))
    (sortedIdx, idxOrder) = sortByKey(idx, iota(n))
    out sortedIdx
    out idxOrder
    (sortedFk, fkPairs) = sortByKey(fk, pairs)
    out sortedFk
    out fkPairs
    (sortedIk, ikValues) = sortByKey(ik, f)
    out sortedIk
    out ikValues
}
"#;

#[derive(Debug, Clone)]
struct Case {
    n: usize,
    m: usize,
    k: usize,
    a: Vec<u32>,
    b: Vec<u32>,
    idx: Vec<u32>,
    perm: Vec<u32>,
    keep: Vec<bool>,
    dst: Vec<u32>,
    f: Vec<f32>,
    flags: Vec<bool>,
    grouped: Vec<u32>,
    src: Vec<u32>,
    /// Sort keys with many duplicates, signed zeros and infinities.
    fk: Vec<f32>,
    ik: Vec<i32>,
    /// `Pair` records as (id, weight).
    pairs: (Vec<u32>, Vec<f32>),
}

/// Sizes 0, 1, primes, and above both the test chunk (64) and the default (4096).
fn case() -> impl Strategy<Value = Case> {
    case_of_size(prop_oneof![
        Just(0usize),
        Just(1),
        Just(7),
        Just(67),
        Just(4099),
        0usize..300
    ])
}

fn case_of_size(n: impl Strategy<Value = usize>) -> impl Strategy<Value = Case> {
    (n, 1usize..50, 1usize..5).prop_flat_map(|(n, m, k)| {
        (
            proptest::collection::vec(any::<u32>(), n),
            proptest::collection::vec(any::<u32>(), n),
            proptest::collection::vec(0..m as u32, n),
            Just((0..n as u32).collect::<Vec<u32>>()).prop_shuffle(),
            proptest::collection::vec(any::<bool>(), n),
            proptest::collection::vec(any::<u32>(), m),
            proptest::collection::vec(-1000.0f32..1000.0, n),
            proptest::collection::vec(prop::bool::weighted(0.1), n),
            proptest::collection::vec(0u32..1000, n * k),
            proptest::collection::vec(any::<u32>(), m),
            (
                proptest::collection::vec(proptest::sample::select(FLOAT_KEYS), n),
                proptest::collection::vec(-3i32..3, n),
                proptest::collection::vec(any::<u32>(), n),
                proptest::collection::vec(-1000.0f32..1000.0, n),
            ),
        )
            .prop_map(
                move |(
                    a,
                    b,
                    idx,
                    perm,
                    keep,
                    dst,
                    f,
                    flags,
                    grouped,
                    src,
                    (fk, ik, ids, weights),
                )| Case {
                    n,
                    m,
                    k,
                    a,
                    b,
                    idx,
                    perm,
                    keep,
                    dst,
                    f,
                    flags,
                    grouped,
                    src,
                    fk,
                    ik,
                    pairs: (ids, weights),
                },
            )
    })
}

/// Float keys that test the sort's order: duplicates, both zeros, both
/// infinities, a subnormal (NaNs: `floats_sort_in_total_order_on_both_backends`).
const FLOAT_KEYS: &[f32] = &[
    -2.5,
    -1.0,
    -0.0,
    0.0,
    1.0e-45,
    0.5,
    1.0,
    f32::INFINITY,
    f32::NEG_INFINITY,
];

/// The same case of `n` elements on every run (proptest's deterministic runner).
fn fixed_case(n: usize) -> Case {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    case_of_size(Just(n))
        .new_tree(&mut runner)
        .unwrap()
        .current()
}

fn compile_case(case: &Case, library: &FunctorLibrary, fuse: bool) -> Plan {
    let overrides = vec![
        ("n".to_string(), case.n.to_string()),
        ("m".to_string(), case.m.to_string()),
        ("k".to_string(), case.k.to_string()),
    ];
    compile_text(
        Path::new("primitives.dpp"),
        PIPELINE,
        library,
        &CompileOptions { fuse, overrides },
    )
    .unwrap_or_else(|e| panic!("{}", e.render(false)))
}

fn data_of(case: &Case) -> crate::data::Data {
    crate::data::Data::new(vec![
        Column::U32(case.a.clone()),
        Column::U32(case.b.clone()),
        Column::U32(case.idx.clone()),
        Column::U32(case.perm.clone()),
        Column::Bool(case.keep.clone()),
        Column::U32(case.dst.clone()),
        Column::F32(case.f.clone()),
        Column::Bool(case.flags.clone()),
        Column::U32(case.grouped.clone()),
        Column::U32(case.src.clone()),
        Column::F32(case.fk.clone()),
        Column::I32(case.ik.clone()),
        pair_column(&case.pairs.0, &case.pairs.1),
    ])
}

fn pair_column(ids: &[u32], weights: &[f32]) -> Column {
    let pair = library().records.find("Pair").unwrap();
    Column::Record {
        ty: pair,
        fields: vec![
            Arc::new(Column::U32(ids.to_vec())),
            Arc::new(Column::F32(weights.to_vec())),
        ],
    }
}

fn run(case: &Case, fuse: bool, threads: usize, chunk: usize) -> HashMap<String, OutputValue> {
    run_result(case, fuse, threads, chunk)
        .outputs
        .into_iter()
        .collect()
}

fn run_result(case: &Case, fuse: bool, threads: usize, chunk: usize) -> RunResult {
    run_result_with_pool(case, fuse, threads, chunk, &ColumnPool::new())
}

fn run_result_with_pool(
    case: &Case,
    fuse: bool,
    threads: usize,
    chunk: usize,
    column_pool: &ColumnPool,
) -> RunResult {
    let library = library();
    let plan = compile_case(case, &library, fuse);
    run_plan_on_cpu(&plan, &library, &data_of(case), threads, chunk, column_pool)
}

fn run_plan_on_cpu(
    plan: &Plan,
    library: &FunctorLibrary,
    data: &crate::data::Data,
    threads: usize,
    chunk: usize,
    column_pool: &ColumnPool,
) -> RunResult {
    let uniforms = Uniforms::default();
    let context = RunContext {
        library,
        uniforms: &uniforms,
        resources: data,
        chunk,
        column_pool,
        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| run_plan(plan, &context)).unwrap()
}

fn run_gpu(case: &Case, fuse: bool, gpu: &GpuContext) -> HashMap<String, OutputValue> {
    run_gpu_result(case, fuse, gpu)
        .outputs
        .into_iter()
        .collect()
}

fn run_gpu_result(case: &Case, fuse: bool, gpu: &GpuContext) -> RunResult {
    let library = library();
    let plan = compile_case(case, &library, fuse);
    run_plan_on_gpu(&plan, &library, &data_of(case), gpu)
}

fn run_plan_on_gpu(
    plan: &Plan,
    library: &FunctorLibrary,
    data: &crate::data::Data,
    gpu: &GpuContext,
) -> RunResult {
    let uniforms = Uniforms::default();
    let context = GpuRunContext {
        gpu,
        library,
        uniforms: &uniforms,
        resources: data,
        profile: false,
    };
    run_plan_gpu(plan, &context).unwrap_or_else(|e| panic!("{e}"))
}

/// Float keys in the total order of docs/language.md §3, sort, NaNs of both
/// signs and several payloads included, each many times (stability): every
/// way of running gives the reference's bits and permutation: the CPU on 1
/// and 2 threads in chunks of 64 and of the default size, fused and not, the
/// GPU with its own binding limit and with one that splits arrays in two.
#[test]
fn floats_sort_in_total_order_on_both_backends() {
    const SOURCE: &str = r#"
param n = 0
pipeline floats {
    keys = iota(n) → map<f32Data>(column: 0)
    (sorted, order) = sortByKey(keys, iota(n))
    out sorted
    out order
}
"#;
    let specials = [
        f32::NAN,
        -0.0,
        0.0,
        -f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::from_bits(0x7F80_0001),
        f32::from_bits(0xFFFF_FFFF),
        1.0,
        -1.0,
        f32::from_bits(1),
        f32::from_bits(0x8000_0001),
        f32::MAX,
        f32::MIN,
        3.0,
    ];
    let library = library();
    let gpu = crate::gpu();
    let split = gpu.map(|gpu| {
        gpu.with_limits(GpuLimits {
            max_binding_bytes: 3000,
            ..gpu.limits
        })
    });
    for n in [0usize, 1, 2, 13, 257, 1399, 4099, 9001] {
        let keys: Vec<f32> = (0..n)
            .map(|i| specials[(i * 7 + i / 5) % specials.len()])
            .collect();
        let order = stable_order(&keys, f32::total_cmp);
        let expected_keys: Vec<u32> = order.iter().map(|&p| keys[p].to_bits()).collect();
        let expected_order: Vec<u32> = order.iter().map(|&p| p as u32).collect();
        let data = crate::data::Data::new(vec![Column::F32(keys)]);
        let check = |result: RunResult, how: &str| {
            let outputs: HashMap<String, OutputValue> = result.outputs.into_iter().collect();
            assert_eq!(
                bits(&f32s(&outputs, "sorted")),
                expected_keys,
                "{n} keys, {how}"
            );
            assert_eq!(u32s(&outputs, "order"), expected_order, "{n} keys, {how}");
        };
        for fuse in [true, false] {
            let options = CompileOptions {
                fuse,
                overrides: vec![("n".to_string(), n.to_string())],
            };
            let plan = compile_text(Path::new("floats.dpp"), SOURCE, &library, &options)
                .unwrap_or_else(|e| panic!("{}", e.render(false)));
            for (threads, chunk) in [
                (1, 64),
                (2, 64),
                (2, dpp_runtime::cpu::kernels::DEFAULT_CHUNK),
            ] {
                let result =
                    run_plan_on_cpu(&plan, &library, &data, threads, chunk, &ColumnPool::new());
                check(
                    result,
                    &format!("CPU, {threads} threads, chunks of {chunk}"),
                );
            }
            if let (Some(gpu), Some(split)) = (gpu, &split) {
                check(run_plan_on_gpu(&plan, &library, &data, gpu), "GPU");
                // Up to 2 segments per array, as in `arrays_split_into_segments_still_match`:
                // more would bind more buffers than a kernel may have.
                if n <= 1400 {
                    check(
                        run_plan_on_gpu(&plan, &library, &data, split),
                        "GPU, split arrays",
                    );
                }
            }
        }
    }
}

fn u32s(outputs: &HashMap<String, OutputValue>, name: &str) -> Vec<u32> {
    match &outputs[name] {
        OutputValue::Array(column) => match column.as_ref() {
            Column::U32(v) => v.clone(),
            other => panic!("{name}: {other:?}"),
        },
        other => panic!("{name}: {other:?}"),
    }
}

fn f32s(outputs: &HashMap<String, OutputValue>, name: &str) -> Vec<f32> {
    match &outputs[name] {
        OutputValue::Array(column) => column.view().as_f32().to_vec(),
        other => panic!("{name}: {other:?}"),
    }
}

fn column(outputs: &HashMap<String, OutputValue>, name: &str) -> Arc<Column> {
    match &outputs[name] {
        OutputValue::Array(column) => column.clone(),
        other => panic!("{name}: {other:?}"),
    }
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|x| x.to_bits()).collect()
}

/// The positions of `keys` in stable ascending order of `compare`.
fn stable_order<K>(keys: &[K], compare: impl Fn(&K, &K) -> std::cmp::Ordering) -> Vec<usize> {
    let mut order: Vec<usize> = (0..keys.len()).collect();
    order.sort_by(|&x, &y| compare(&keys[x], &keys[y]));
    order
}

/// `sort` and `sortByKey` against Rust's stable sorts (`f32::total_cmp` is
/// the order of docs/language.md §3, sort).
fn check_sorts_against_reference(case: &Case, outputs: &HashMap<String, OutputValue>) {
    let Case {
        a,
        b,
        idx,
        f,
        fk,
        ik,
        pairs,
        ..
    } = case;
    let mut sorted_a = a.clone();
    sorted_a.sort();
    assert_eq!(u32s(outputs, "sortedA"), sorted_a);
    let mut sums: Vec<u32> = a.iter().zip(b).map(|(x, y)| x.wrapping_add(*y)).collect();
    sums.sort();
    assert_eq!(u32s(outputs, "sortedSums"), sums);
    let order = stable_order(idx, u32::cmp);
    let pick_u32 = |values: &[u32]| -> Vec<u32> { order.iter().map(|&p| values[p]).collect() };
    assert_eq!(u32s(outputs, "sortedIdx"), pick_u32(idx));
    let positions: Vec<u32> = order.iter().map(|&p| p as u32).collect();
    assert_eq!(u32s(outputs, "idxOrder"), positions, "stable");
    let order = stable_order(fk, f32::total_cmp);
    let sorted_fk: Vec<f32> = order.iter().map(|&p| fk[p]).collect();
    assert_eq!(bits(&f32s(outputs, "sortedFk")), bits(&sorted_fk));
    let ids: Vec<u32> = order.iter().map(|&p| pairs.0[p]).collect();
    let weights: Vec<f32> = order.iter().map(|&p| pairs.1[p]).collect();
    assert_eq!(*column(outputs, "fkPairs"), pair_column(&ids, &weights));
    let order = stable_order(ik, i32::cmp);
    let sorted_ik: Vec<i32> = order.iter().map(|&p| ik[p]).collect();
    assert_eq!(column(outputs, "sortedIk").view().as_i32(), sorted_ik);
    let moved: Vec<f32> = order.iter().map(|&p| f[p]).collect();
    assert_eq!(bits(&f32s(outputs, "ikValues")), bits(&moved));
}

fn host(outputs: &HashMap<String, OutputValue>, name: &str) -> HostValue {
    match &outputs[name] {
        OutputValue::Host(v) => *v,
        other => panic!("{name}: {other:?}"),
    }
}

fn segmented_scan(
    values: &[u32],
    flags: &[bool],
    inclusive: bool,
    identity: u32,
    op: impl Fn(u32, u32) -> u32,
) -> Vec<u32> {
    let mut running = identity;
    values
        .iter()
        .zip(flags)
        .map(|(&v, &starts)| {
            if starts {
                running = identity;
            }
            let before = running;
            running = op(running, v);
            if inclusive {
                running
            } else {
                before
            }
        })
        .collect()
}

fn check_against_reference(case: &Case, outputs: &HashMap<String, OutputValue>) {
    let Case {
        n,
        k,
        a,
        b,
        idx,
        perm,
        keep,
        dst,
        f,
        flags,
        grouped,
        src,
        ..
    } = case;
    let added: Vec<u32> = a.iter().zip(b).map(|(x, y)| x.wrapping_add(*y)).collect();
    assert_eq!(u32s(outputs, "added"), added);
    let gathered: Vec<u32> = idx.iter().map(|&i| src[i as usize]).collect();
    assert_eq!(u32s(outputs, "gathered"), gathered);
    let group_sums: Vec<u32> = grouped
        .chunks(*k)
        .map(|g| g.iter().fold(0u32, |s, x| s.wrapping_add(*x)))
        .collect();
    assert_eq!(u32s(outputs, "groupSums"), group_sums);
    let pair_sums: Vec<u32> = (a.iter().zip(grouped.chunks(*k)))
        .map(|(x, g)| {
            g.iter()
                .fold(0u32, |s, y| s.wrapping_add(x.wrapping_mul(*y)))
        })
        .collect();
    assert_eq!(u32s(outputs, "pairSums"), pair_sums);
    let lane_sums: Vec<u32> = (b.iter())
        .map(|x| (0..*k as u32).fold(0u32, |s, j| s.wrapping_add(x.wrapping_add(j))))
        .collect();
    assert_eq!(u32s(outputs, "laneSums"), lane_sums);
    let mut permuted = vec![0u32; *n];
    let mut masked = vec![0u32; *n];
    for i in 0..*n {
        permuted[perm[i] as usize] = a[i];
        if keep[i] {
            masked[perm[i] as usize] = a[i];
        }
    }
    assert_eq!(u32s(outputs, "permuted"), permuted);
    assert_eq!(u32s(outputs, "masked"), masked);
    let mut overwritten = dst.clone();
    let mut combined = dst.clone();
    for i in 0..*n {
        overwritten[idx[i] as usize] = a[i];
        combined[idx[i] as usize] = combined[idx[i] as usize].wrapping_add(a[i]);
    }
    assert_eq!(
        u32s(outputs, "overwritten"),
        overwritten,
        "last writer wins"
    );
    assert_eq!(u32s(outputs, "combined"), combined);
    let acc_seen: Vec<u32> = idx.iter().map(|&i| overwritten[i as usize]).collect();
    assert_eq!(u32s(outputs, "accSeen"), acc_seen);
    assert_eq!(u32s(outputs, "accOverwritten"), overwritten);
    let mut own = dst.clone();
    for _round in 0..2 {
        for i in 0..*n {
            own[idx[i] as usize] = own[idx[i] as usize].wrapping_add(b[i]);
        }
    }
    assert_eq!(u32s(outputs, "ownTwice"), own);
    let repeated: Vec<u32> = a.iter().flat_map(|&x| std::iter::repeat_n(x, *k)).collect();
    assert_eq!(u32s(outputs, "repeated"), repeated);
    let lanes: Vec<u32> = (0..*n).flat_map(|_| 0..*k as u32).collect();
    assert_eq!(u32s(outputs, "lanes"), lanes);
    let total = a.iter().fold(0u32, |s, x| s.wrapping_add(*x));
    assert_eq!(host(outputs, "total"), HostValue::Int(total as i64));
    assert_eq!(
        host(outputs, "smallest"),
        HostValue::Int(a.iter().copied().min().unwrap_or(u32::MAX) as i64)
    );
    let fsum: f64 = f.iter().map(|x| *x as f64).sum();
    let got = host(outputs, "fsum").as_f64().unwrap();
    assert!(
        (got - fsum).abs() <= 1e-3 * (1.0 + fsum.abs()) + 0.1,
        "fsum {got} vs {fsum}"
    );
    let no_flags = vec![false; *n];
    let add = |x: u32, y: u32| x.wrapping_add(y);
    assert_eq!(
        u32s(outputs, "inclusive"),
        segmented_scan(a, &no_flags, true, 0, add)
    );
    assert_eq!(
        u32s(outputs, "exclusive"),
        segmented_scan(a, &no_flags, false, 0, add)
    );
    assert_eq!(
        u32s(outputs, "segmentedInclusive"),
        segmented_scan(a, flags, true, 0, add)
    );
    assert_eq!(
        u32s(outputs, "segmentedExclusive"),
        segmented_scan(a, flags, false, 0, u32::max)
    );
    let mut running = 0.0f64;
    for (got, x) in f32s(outputs, "fscan").iter().zip(f) {
        running += *x as f64;
        assert!((*got as f64 - running).abs() <= 1e-3 * (1.0 + running.abs()) + 0.1);
    }
    check_sorts_against_reference(case, outputs);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn every_primitive_matches_its_sequential_reference(case in case()) {
        let fused_one_thread = run(&case, true, 1, 64);
        check_against_reference(&case, &fused_one_thread);
        // Same bits, floats included, whatever the fusion and thread count.
        prop_assert_eq!(&fused_one_thread, &run(&case, true, 2, 64));
        prop_assert_eq!(&fused_one_thread, &run(&case, false, 2, 64));
    }
}

/// The pairs' and the copies' sums above run in nested stages, so the
/// tests of every primitive cover them on both backends.
#[test]
fn the_pair_and_lane_sums_run_in_nested_stages() {
    let plan = compile_case(&fixed_case(7), &library(), true);
    let closed: Vec<&str> = (plan.stages().iter())
        .filter_map(|stage| stage.closing_group_gather())
        .map(|op| plan.var(op.outputs[0]).name.as_str())
        .collect();
    assert_eq!(closed, ["pairSums", "laneSums"]);
}

#[test]
fn default_chunk_size_agrees_with_small_chunks() {
    let case = fixed_case(4099);
    let small = run(&case, true, 2, 64);
    check_against_reference(&case, &small);
    // A different chunk size may round float sums differently; integers must agree.
    let default = run(&case, true, 2, dpp_runtime::cpu::kernels::DEFAULT_CHUNK);
    for name in [
        "added",
        "gathered",
        "permuted",
        "combined",
        "inclusive",
        "segmentedExclusive",
    ] {
        assert_eq!(u32s(&small, name), u32s(&default, name), "{name}");
    }
}

/// The CPU backend says where each stage's time went, op by op, so a fused
/// stage's profile is not one opaque number: an entry per op in stage order,
/// named after the pipeline's variable where the op makes one, timed inside
/// the stage (on 2 threads the ops cannot add up to more than twice its wall
/// time), a compiled run of element-wise ops one row. A GPU stage is one
/// kernel: no split.
#[test]
fn fused_stages_are_timed_op_by_op_on_the_cpu() {
    let case = fixed_case(20_000);
    let library = library();
    let plan = compile_case(&case, &library, true);
    let result = run_result(&case, true, 2, dpp_runtime::cpu::kernels::DEFAULT_CHUNK);
    let stages = plan.stages();
    assert_eq!(result.profile.len(), stages.len());
    let mut labels = Vec::new();
    for (timing, stage) in result.profile.iter().zip(&stages) {
        // After the ops, the copying of what the stage stores, if it stores any.
        let stores = !dpp_runtime::interpret::elementwise_materialised(stage).is_empty();
        assert_eq!(
            timing.ops.len(),
            stage.ops.len() + usize::from(stores),
            "{}",
            timing.label
        );
        if stores {
            let store = timing.ops.last().unwrap();
            assert!(store.label.starts_with("store"), "{}", store.label);
        }
        let op_time: std::time::Duration = timing.ops.iter().map(|op| op.thread_time).sum();
        assert!(
            op_time <= 2 * timing.time,
            "{}: {op_time:?} in {:?}",
            timing.label,
            timing.time
        );
        labels.extend(timing.ops.iter().map(|op| op.label.clone()));
    }
    for expected in [
        // Compiled into one loop (`cpu::compiled`): one row for both ops.
        "compiled[2]: added = map<add> … gathered = gather",
        "permuted = scatter",
        "reduce<add>",
        "iota",
        "store added, gathered",
    ] {
        assert!(
            labels.iter().any(|l| l == expected),
            "{expected} not in {labels:?}"
        );
    }
    // The stage that adds `a` and `b` has its ops timed, not left at zero.
    let adding = result
        .profile
        .iter()
        .find(|t| t.ops.iter().any(|op| op.label.contains("added = map<add>")))
        .unwrap();
    assert!(
        adding.ops.iter().any(|op| !op.thread_time.is_zero()),
        "{adding:?}"
    );
    if let Some(gpu) = crate::gpu() {
        let result = run_gpu_result(&case, true, gpu);
        assert!(
            result.profile.iter().all(|t| t.ops.is_empty()),
            "{:?}",
            result.profile
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// The GPU backend runs every primitive form to the same results: integers
    /// bit for bit, float sums within rounding (they add in another order).
    #[test]
    fn every_primitive_on_the_gpu_matches_the_reference(case in case()) {
        let Some(gpu) = crate::gpu() else { return Ok(()) };
        let fused = run_gpu(&case, true, gpu);
        check_against_reference(&case, &fused);
        check_against_reference(&case, &run_gpu(&case, false, gpu));
    }
}

/// Arrays longer than the adapter's largest binding are split into segments:
/// with a 3000-byte limit every u32 array of this case has 2 segments, and
/// the results still match.
#[test]
fn arrays_split_into_segments_still_match() {
    let Some(gpu) = crate::gpu() else { return };
    let small = gpu.with_limits(GpuLimits {
        max_binding_bytes: 3000,
        ..gpu.limits
    });
    let case = fixed_case(1400);
    check_against_reference(&case, &run_gpu(&case, true, &small));
    check_against_reference(&case, &run_gpu(&case, false, &small));
}

/// More workgroups than the adapter allows along one dimension are
/// dispatched in two: with at most 16 per dimension, 4099 elements need 65
/// workgroups of 64, so 16 × 5.
#[test]
fn many_workgroups_use_a_two_dimensional_dispatch() {
    let Some(gpu) = crate::gpu() else { return };
    let narrow = gpu.with_limits(GpuLimits {
        max_workgroups_per_dimension: 16,
        ..gpu.limits
    });
    let case = fixed_case(4099);
    check_against_reference(&case, &run_gpu(&case, true, &narrow));
}

/// A run reuses the device buffers of the runs before it (new device memory
/// is slow to get), which still hold those runs' values: where a new buffer
/// would be zero (a combining scatter's target, a fan-out's or a scan's
/// partial results), the reused one must be cleared first.
#[test]
fn runs_that_reuse_buffers_still_start_from_zero() {
    let Some(gpu) = crate::gpu() else { return };
    // A context with its own, empty pool, so that the runs below reuse each
    // other's buffers.
    let own_pool = gpu.with_limits(gpu.limits);
    let case = fixed_case(4099);
    for _ in 0..3 {
        check_against_reference(&case, &run_gpu(&case, true, &own_pool));
        check_against_reference(&case, &run_gpu(&case, false, &own_pool));
    }
}

/// The CPU backend takes its arrays from a pool that earlier runs (and a
/// loop's earlier rounds) gave theirs back to, old values and all: where a
/// new array would be zero (a scatter's unwritten slots), the reused one must
/// be cleared first. The pool starts full of arrays of every type and of
/// lengths 1.5× apart, holding garbage, enough of each that every array the
/// first run asks for is one of them.
#[test]
fn runs_that_reuse_cpu_arrays_still_start_from_zero() {
    let case = fixed_case(4099);
    let pool = ColumnPool::keeping_every_size();
    let mut len = 1;
    while len < 1 << 15 {
        for _ in 0..16 {
            for garbage in [
                Column::Bool(vec![true; len]),
                Column::U32(vec![0xdead_beef; len]),
                Column::I32(vec![-7; len]),
                Column::F32(vec![f32::NAN; len]),
            ] {
                pool.give(Arc::new(garbage));
            }
        }
        len += len / 2 + 1;
    }
    for fuse in [true, false, true, false] {
        let outputs: HashMap<_, _> = run_result_with_pool(&case, fuse, 2, 64, &pool)
            .outputs
            .into_iter()
            .collect();
        check_against_reference(&case, &outputs);
    }
    assert!(pool.reused() > 50, "only {} arrays reused", pool.reused());
}

/// Arrays come back from the device in read-back pieces of a few MiB (see
/// `READ_BACK_PIECE_BYTES`): a record array of 12-byte fields longer than a
/// piece, split into binding segments that are not multiples of the piece,
/// reads back element for element.
#[test]
fn large_arrays_read_back_across_pieces_and_segments() {
    use dpp_gpu::array::{download, upload};
    let Some(gpu) = crate::gpu() else { return };
    let segmented = gpu.with_limits(GpuLimits {
        max_binding_bytes: 3_000_000,
        ..gpu.limits
    });
    let n = 1_000_003;
    let vectors = Column::Vec3(
        (0..n)
            .map(|i| glam::Vec3::new(i as f32, -(i as f32), 0.5 * i as f32))
            .collect(),
    );
    let flags = Column::Bool((0..n).map(|i| i % 3 == 0).collect());
    for column in [vectors, flags] {
        for context in [gpu, &segmented] {
            let on_device = upload(context, &column).unwrap();
            let back = download(context, &on_device, &Default::default()).unwrap();
            assert!(
                back == column,
                "{:?} read back differently",
                column.elem_type()
            );
        }
    }
}
