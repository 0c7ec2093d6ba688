//! `dpp bench`'s results as markdown tables (in the manner of the paper's
//! tables) and as JSON.

use super::{ms, Engine, Measurement, SceneResult, SideBySide, ViewResult, AGREEMENT};
use dpp_gpu::GpuContext;
use dpp_runtime::interpret::listed_op_shares;
use serde_json::{json, Value};
use std::fmt::Write;

/// The adapter a `--backend gpu` bench ran on (wgpu's `AdapterInfo`), and how
/// its stages were timed.
#[derive(Clone, Debug)]
pub struct GpuInfo {
    pub name: String,
    /// The API wgpu drives it through: Vulkan, Metal, Dx12, Gl.
    pub api: String,
    pub device_type: String,
    pub driver: String,
    pub driver_info: String,
    /// Whether the adapter has timestamp queries (stage times on the device).
    pub timestamps: bool,
}

impl GpuInfo {
    pub fn of(gpu: &GpuContext) -> GpuInfo {
        GpuInfo {
            name: gpu.info.name.clone(),
            api: format!("{:?}", gpu.info.backend),
            device_type: format!("{:?}", gpu.info.device_type),
            driver: gpu.info.driver.clone(),
            driver_info: gpu.info.driver_info.clone(),
            timestamps: gpu.timestamps,
        }
    }

    /// `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu; driver llvmpipe, Mesa 22.3.6)`.
    pub fn describe(&self) -> String {
        let driver = [self.driver.as_str(), self.driver_info.as_str()]
            .into_iter()
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join(", ");
        if driver.is_empty() {
            format!("{} ({}, {})", self.name, self.api, self.device_type)
        } else {
            format!(
                "{} ({}, {}; driver {driver})",
                self.name, self.api, self.device_type
            )
        }
    }

    /// What the stage times are.
    fn stage_timing(&self) -> &'static str {
        if self.timestamps {
            "timestamp queries"
        } else {
            "host"
        }
    }
}

pub struct Report {
    pub cpu: String,
    /// The adapter, when the GPU backend ran the plans; `None` for the CPU backend.
    pub gpu: Option<GpuInfo>,
    pub threads: usize,
    /// How the CPU backend ran element-wise ops (`--cpu-elementwise`).
    pub cpu_elementwise: crate::CpuElementwise,
    /// How dpp's BVH was built (`--bvh`).
    pub bvh: crate::BvhChoice,
    pub size: (u32, u32),
    pub warmup: u32,
    pub rounds: u32,
    /// Embree's triangle test, when Embree ran.
    pub embree_test: Option<super::EmbreeTest>,
    /// Compiling WORKLOAD2's fused plan, part of its time to first image.
    pub workload2_compile_ms: Option<f64>,
    pub scenes: Vec<SceneResult>,
}

fn mrays(rays: u64, ms: f64) -> f64 {
    rays as f64 / (ms * 1e3)
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

/// The median of `values` (the mean of the middle two for an even count).
fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    match sorted.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => sorted[n / 2],
        n => (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0,
    }
}

fn minimum(values: &[f64]) -> f64 {
    values.iter().copied().fold(f64::INFINITY, f64::min)
}

/// A table cell: [`Measurement::beyond_traversal_ns_per_pixel`], or `–`.
fn beyond_traversal(measurement: &Measurement, pixels: u64) -> String {
    (measurement.beyond_traversal_ns_per_pixel(pixels))
        .map_or("–".into(), |ns| format!("{ns:.1}"))
}

impl Report {
    /// Which triangle test Embree's scene had, for the Embree sections.
    fn embree_test_words(&self) -> &'static str {
        match self.embree_test {
            Some(super::EmbreeTest::Fast) => "Embree's scene has its default triangle test, faster than its robust one and not watertight (`--embree-test fast`)",
            Some(super::EmbreeTest::Robust) | None => "Embree's scene has its robust, watertight triangle test (`--embree-test robust`, the default)",
        }
    }

    fn has_workload(&self, workload: u32) -> bool {
        self.scenes
            .iter()
            .flat_map(|s| &s.views)
            .flat_map(|v| &v.workloads)
            .any(|w| w.workload == workload)
    }

    fn has_embree_builds(&self) -> bool {
        self.scenes.iter().any(|s| s.embree_build_ms.is_some())
    }

    fn has_engines(&self) -> bool {
        self.scenes
            .iter()
            .flat_map(|s| &s.views)
            .any(|v| !v.engines.is_empty())
    }

    fn has_engine_frames(&self, workload: u32) -> bool {
        self.scenes
            .iter()
            .flat_map(|s| &s.views)
            .flat_map(|v| &v.engine_frames)
            .any(|r| r.workload == workload)
    }

    /// WORKLOAD2's or WORKLOAD3's fused frame with dpp's traversal and with
    /// Embree's.
    fn write_engine_frames(&self, md: &mut String, workload: u32) {
        let _ = writeln!(
            md,
            "## WORKLOAD{workload}: dpp against Embree, fused frame ms\n"
        );
        let test = self.embree_test_words();
        // WORKLOAD2 traces only closest hits, and its bar is its frame over the
        // intersection of the same rays; WORKLOAD3 also traces any-hit rays.
        let (calls, last_heading, last_words) = if workload == 2 {
            (
                "`intersect` (`rtcIntersect1` per ray, or `rtcIntersect16` packets)",
                "frame / W1 intersect",
                "the fused frame over WORKLOAD1's `map<intersect>` stage (unfused) with the same engine, on the same rays",
            )
        } else {
            (
                "`intersect` and `occluded` (`rtcIntersect1` and `rtcOccluded1` per ray, or the 16-ray packet calls)",
                "`occluded` thread ms",
                "the thread time inside the `map<occluded>` ops (occlusion and shadow rays, any hit)",
            )
        };
        let _ = writeln!(md, "The fused WORKLOAD{workload} plan with Embree behind {calls}; everything else is the same. {test}. Ratio: Embree's time over dpp's. The last three columns, dpp / Embree single / Embree packet: the thread time (ms, summed over the threads) inside the `map<intersect>` ops (closest hit), the frame's wall time outside the traversal in ns per pixel (as in the frames-per-second table), and {last_words}.\n");
        let _ = writeln!(md, "| scene | view | dpp | Embree single | Embree packet | single / dpp | packet / dpp | `intersect` thread ms | beyond the traversal, ns/pixel | {last_heading} |");
        let _ = writeln!(
            md,
            "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
        );
        for scene in &self.scenes {
            for view in &scene.views {
                let Some(own) = view.workloads.iter().find(|w| w.workload == workload) else {
                    continue;
                };
                let [single, packet] = [Engine::EmbreeSingle, Engine::EmbreePacket]
                    .map(|e| view.engine_frame(workload, e));
                let frame = |m: Option<&Measurement>| {
                    m.map_or("–".into(), |m| format!("{:.1}", m.mean_ms()))
                };
                let ratio = |m: Option<&Measurement>| {
                    m.map_or("–".into(), |m| {
                        format!("{:.2}", m.mean_ms() / own.fused.mean_ms())
                    })
                };
                let threads = |functor: &str| {
                    [Some(&own.fused), single, packet]
                        .iter()
                        .map(|m| {
                            m.map_or("–".into(), |m| format!("{:.0}", m.map_thread_ms(functor)))
                        })
                        .collect::<Vec<String>>()
                        .join(" / ")
                };
                let last = if workload == 2 {
                    // Each engine's frame over its own WORKLOAD1 intersection.
                    let intersects = [
                        view.workload1_intersect_ms(),
                        view.engine_workload1_intersect_ms(Engine::EmbreeSingle),
                        view.engine_workload1_intersect_ms(Engine::EmbreePacket),
                    ];
                    [Some(&own.fused), single, packet]
                        .iter()
                        .zip(intersects)
                        .map(|pair| match pair {
                            (Some(frame), Some(intersect)) => {
                                format!("{:.2}×", frame.mean_ms() / intersect)
                            }
                            _ => "–".into(),
                        })
                        .collect::<Vec<String>>()
                        .join(" / ")
                } else {
                    threads("occluded")
                };
                let beyond = [Some(&own.fused), single, packet]
                    .iter()
                    .map(|m| m.map_or("–".into(), |m| beyond_traversal(m, view.rays)))
                    .collect::<Vec<String>>()
                    .join(" / ");
                let _ = writeln!(
                    md,
                    "| {} | {} | {:.1} | {} | {} | {} | {} | {} | {} | {} |",
                    scene.name,
                    view.view,
                    own.fused.mean_ms(),
                    frame(single),
                    frame(packet),
                    ratio(single),
                    ratio(packet),
                    threads("intersect"),
                    beyond,
                    last,
                );
            }
        }
        md.push('\n');
    }

    /// Each BVH's build time beside its trace rate: WORKLOAD1's
    /// `map<intersect>` over the views, with dpp's traversal of its own BVH
    /// and with Embree's single rays and packets on each of its two scenes.
    fn write_bvh_builds(&self, md: &mut String) {
        let _ = writeln!(md, "## BVH builds and their trace rates\n");
        let embree = if self.has_embree_builds() {
            "; Embree: copying the mesh into its buffers and `rtcCommitScene`, at its default quality, `RTC_BUILD_QUALITY_MEDIUM`, and at `RTC_BUILD_QUALITY_HIGH`"
        } else {
            ""
        };
        let own_build = match self.bvh {
            crate::BvhChoice::Sah => "our binned SAH build",
            crate::BvhChoice::Ploc => "obvhs's PLOC build and our flattening",
            crate::BvhChoice::Lbvh => "the linear BVH: Morton codes, a radix sort, the radix tree",
        };
        let _ = writeln!(md, "Build: the BVH of the loaded mesh (dpp: {own_build}{embree}). Trace rate: WORKLOAD1's primary rays over its `map<intersect>` stage (unfused plan), mean over the views, with that BVH behind `intersect`.\n");
        let _ = writeln!(
            md,
            "| scene | BVH | build ms | build / dpp's | `map<intersect>` Mrays/s | rate / dpp's |"
        );
        let _ = writeln!(md, "| --- | --- | ---: | ---: | ---: | ---: |");
        for scene in &self.scenes {
            let rate = |intersect_ms: &dyn Fn(&super::ViewResult) -> Option<f64>| {
                let rates: Vec<f64> = (scene.views.iter())
                    .filter_map(|view| intersect_ms(view).map(|t| mrays(view.rays, t)))
                    .collect();
                (!rates.is_empty()).then(|| mean(&rates))
            };
            let own_rate = rate(&|view| view.workload1_intersect_ms());
            let mut row = |bvh: &str, build: Option<f64>, rate: Option<f64>| {
                let ratio = |value: Option<f64>, own: Option<f64>| match (value, own) {
                    (Some(value), Some(own)) => format!("{:.2}", value / own),
                    _ => "–".into(),
                };
                let _ = writeln!(
                    md,
                    "| {} | {bvh} | {} | {} | {} | {} |",
                    scene.name,
                    build.map_or("–".into(), |v| format!("{v:.1}")),
                    ratio(build, Some(scene.bvh_ms)),
                    rate.map_or("–".into(), |v| format!("{v:.2}")),
                    ratio(rate, own_rate),
                );
            };
            let own_bvh = match self.bvh {
                crate::BvhChoice::Sah => "dpp (binned SAH)",
                crate::BvhChoice::Ploc => "dpp (obvhs PLOC)",
                crate::BvhChoice::Lbvh => "dpp (linear BVH)",
            };
            row(own_bvh, Some(scene.bvh_ms), own_rate);
            for (engine, bvh, build) in [
                (
                    Engine::EmbreeSingle,
                    "Embree default, single rays",
                    scene.embree_build_ms,
                ),
                (
                    Engine::EmbreePacket,
                    "Embree default, 16-ray packets",
                    scene.embree_build_ms,
                ),
                (
                    Engine::EmbreeSingleHigh,
                    "Embree high, single rays",
                    scene.embree_high_build_ms,
                ),
                (
                    Engine::EmbreePacketHigh,
                    "Embree high, 16-ray packets",
                    scene.embree_high_build_ms,
                ),
            ] {
                if build.is_some() {
                    row(
                        bvh,
                        build,
                        rate(&|view| view.engine_workload1_intersect_ms(engine)),
                    );
                }
            }
        }
        md.push('\n');
    }

    /// WORKLOAD2's time to first image on each scene's first view: what
    /// `dpp run` does before its first image is in memory, part by part, with
    /// dpp's BVH and with each of Embree's behind `intersect` (16-ray packets).
    fn write_time_to_first_image(&self, md: &mut String) {
        let _ = writeln!(md, "## Time to first image: WORKLOAD2\n");
        let embree = if self.has_embree_builds() {
            "; with Embree, its BVH instead of dpp's and its 16-ray packets behind `intersect`, the rest the same"
        } else {
            ""
        };
        let _ = writeln!(md, "Compiling the fused plan, loading the mesh, its vertex normals, the BVH and the first fused frame on the first view (no arrays of an earlier frame to reuse){embree}. Last column: the time to first image over dpp's.\n");
        let _ = writeln!(md, "| scene | view | BVH | compile ms | load ms | normals ms | BVH ms | first frame ms | time to first image ms | / dpp's |");
        let _ = writeln!(
            md,
            "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
        );
        let compile = self.workload2_compile_ms.unwrap_or(0.0);
        for scene in &self.scenes {
            let Some(view) = scene.views.first() else {
                continue;
            };
            let Some(own) = view.workloads.iter().find(|w| w.workload == 2) else {
                continue;
            };
            let shared = compile + scene.load_ms + scene.normals_ms;
            let own_total = shared + scene.bvh_ms + own.fused.first_frame_ms;
            let mut row = |bvh: &str, build: f64, frame: f64| {
                let total = shared + build + frame;
                let _ = writeln!(
                    md,
                    "| {} | {} | {bvh} | {compile:.1} | {:.1} | {:.1} | {build:.1} | {frame:.1} | {total:.1} | {:.2} |",
                    scene.name, view.view, scene.load_ms, scene.normals_ms, total / own_total
                );
            };
            row("dpp", scene.bvh_ms, own.fused.first_frame_ms);
            for (engine, bvh, build) in [
                (
                    Engine::EmbreePacket,
                    "Embree default",
                    scene.embree_build_ms,
                ),
                (
                    Engine::EmbreePacketHigh,
                    "Embree high",
                    scene.embree_high_build_ms,
                ),
            ] {
                if let (Some(build), Some(frame)) = (build, view.engine_frame(2, engine)) {
                    row(bvh, build, frame.first_frame_ms);
                }
            }
        }
        md.push('\n');
    }

    /// Every view's pairs of plans measured in turn that `pairs` picks.
    fn pairs_in_turn<'a, I: Iterator<Item = &'a SideBySide>>(
        &'a self,
        pairs: impl Fn(&'a ViewResult) -> I,
    ) -> Vec<(&'a SceneResult, &'a ViewResult, &'a SideBySide)> {
        (self.scenes.iter())
            .flat_map(|scene| scene.views.iter().map(move |view| (scene, view)))
            .flat_map(|(scene, view)| pairs(view).map(move |pair| (scene, view, pair)))
            .collect()
    }

    /// `--versus`: both files' frames on every view and their ratio.
    fn write_side_by_side(&self, md: &mut String) {
        let rows = self.pairs_in_turn(|view| view.side_by_side.iter());
        let Some((_, _, first)) = rows.first() else {
            return;
        };
        let (own, versus) = (&first.own, &first.versus);
        let _ = writeln!(
            md,
            "## `{versus}` against `{own}` (WORKLOAD{}), fused frame ms, side by side\n",
            first.workload
        );
        let _ = writeln!(
            md,
            "Each round runs a frame of each file, one after the other (the first of the two alternating), after the warm-up rounds; a ratio is `{versus}`'s frame over `{own}`'s, and its median is over the rounds' ratios.\n"
        );
        write_in_turn_table(md, &rows);
    }

    /// With Embree: dpp and Embree's packets in turn, the bars' comparison.
    fn write_engines_in_turn(&self, md: &mut String) {
        let rows = self.pairs_in_turn(|view| view.engines_in_turn.iter());
        if rows.is_empty() {
            return;
        }
        let _ = writeln!(md, "## dpp and Embree's packets in turn, ms\n");
        let _ = writeln!(
            md,
            "Each round runs the plan with dpp's traversal and with Embree's 16-ray packets behind `intersect` and `occluded` ({}), one after the other (the first of the two alternating), after the warm-up rounds: WORKLOAD1's unfused `map<intersect>` stage, WORKLOAD3's fused frame. A ratio is Embree's time over dpp's (above 1: dpp is faster), and its median is over the rounds' ratios.\n",
            self.embree_test_words()
        );
        write_in_turn_table(md, &rows);
    }

    pub fn markdown(&self) -> String {
        let mut md = String::new();
        let (width, height) = self.size;
        let _ = writeln!(md, "# dpp bench\n");
        match &self.gpu {
            None => {
                let _ = writeln!(
                    md,
                    "{} ({} threads), {width}x{height}, {} warm-up + {} measured rounds per plan (times are means); element-wise ops {}.\n",
                    self.cpu,
                    self.threads,
                    self.warmup,
                    self.rounds,
                    match self.cpu_elementwise {
                        crate::CpuElementwise::Compiled => "compiled into loops",
                        crate::CpuElementwise::Columns => "column at a time",
                    }
                );
            }
            Some(gpu) => {
                let _ = writeln!(
                    md,
                    "GPU backend: {}; host {} ({} threads), {width}x{height}, {} warm-up + {} measured rounds per plan (times are means).\n",
                    gpu.describe(),
                    self.cpu,
                    self.threads,
                    self.warmup,
                    self.rounds
                );
                let timing = if gpu.timestamps {
                    "device time, from timestamp queries at the start and end of each stage's compute pass (host time around the wait where the driver reports none)"
                } else {
                    "host time, from submitting each stage to the end of the wait for it (this adapter has no timestamp queries)"
                };
                let _ = writeln!(
                    md,
                    "The device is opened once for the whole bench, outside every frame. A plan's first run on the device compiles its kernels and a scene's first run uploads the scene's buffers: the warm-up rounds absorb both (with `--warmup 0` they fall in the first measured frame). A frame is the host's wall time of a whole run: uniforms, every stage, waiting for the device, and the outputs downloaded to host memory; the measured frames run without profiling. Stage times come from {} further run{} with profiling, which wait{} for the device after every stage: {timing}.\n",
                    self.rounds,
                    if self.rounds == 1 { "" } else { "s" },
                    if self.rounds == 1 { "s" } else { "" },
                );
            }
        }

        let _ = writeln!(md, "## Scenes\n");
        let embree = self.has_embree_builds();
        let _ = writeln!(
            md,
            "| scene | triangles | load ms | normals ms | BVH build ms |{}",
            if embree { " Embree build ms |" } else { "" }
        );
        let _ = writeln!(
            md,
            "| --- | ---: | ---: | ---: | ---: |{}",
            if embree { " ---: |" } else { "" }
        );
        for scene in &self.scenes {
            let _ = write!(
                md,
                "| {} | {} | {:.1} | {:.1} | {:.1} |",
                scene.name, scene.triangles, scene.load_ms, scene.normals_ms, scene.bvh_ms
            );
            if embree {
                let _ = write!(
                    md,
                    " {} |",
                    scene
                        .embree_build_ms
                        .map_or("–".into(), |v| format!("{v:.1}"))
                );
            }
            md.push('\n');
        }
        md.push('\n');
        self.write_bvh_builds(&mut md);
        if self.has_workload(2) {
            self.write_time_to_first_image(&mut md);
        }

        if self.has_workload(1) {
            let _ = writeln!(md, "## WORKLOAD1 (primary rays), Mrays/s\n");
            let _ = writeln!(md, "`map<intersect>`: primary rays over the time of that stage alone (unfused plan); frame: over the whole frame.\n");
            let _ = writeln!(md, "| scene | view | rays | `map<intersect>` | frame, fused | frame, unfused | fusion gain |");
            let _ = writeln!(md, "| --- | --- | ---: | ---: | ---: | ---: | ---: |");
            for scene in &self.scenes {
                for view in &scene.views {
                    for w in view.workloads.iter().filter(|w| w.workload == 1) {
                        let _ = writeln!(
                            md,
                            "| {} | {} | {} | {} | {:.2} | {:.2} | {:.2}× |",
                            scene.name,
                            view.view,
                            view.rays,
                            w.unfused
                                .intersect_ms()
                                .map_or("–".into(), |t| format!("{:.2}", mrays(view.rays, t))),
                            mrays(view.rays, w.fused.mean_ms()),
                            mrays(view.rays, w.unfused.mean_ms()),
                            w.fusion_gain()
                        );
                    }
                }
            }
            md.push('\n');
        }

        if self.has_engines() {
            let _ = writeln!(
                md,
                "## WORKLOAD1: dpp against Embree, `map<intersect>` Mrays/s\n"
            );
            let _ = writeln!(md, "The same pipeline with Embree behind `intersect` (`rtcIntersect1` per ray, or `rtcIntersect16` packets). {}. Ratio: dpp's rate over Embree's. Hits: rays that hit, dpp / Embree; same triangle: rays for which both name the same triangle or both miss, and (+) rays that hit different triangles at the same distance (overlapping triangles, a tie). Where one engine hits a ray the other misses, the hits cell says how many such rays there were, and how many of them meet the hit triangle's plane at its border (within a ten-thousandth of its size, or of {} f32 rounding steps at its corners' distance from the eye, in f64: where the two watertight tests may round either way). They agree (✗ where not) when all such rays but {} per million are at a border and the two shares add up, with the one-sided rays at a border, to {:.1}% or more.\n", self.embree_test_words(), super::BORDER_ROUNDING_STEPS, super::ONE_SIDED_RAYS_PER_MILLION, 100.0 * AGREEMENT);
            let _ = writeln!(md, "| scene | view | dpp | Embree single | Embree packet | dpp / single | dpp / packet | hits (single) | hits (packet) | same triangle (single / packet) |");
            let _ = writeln!(
                md,
                "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
            );
            for scene in &self.scenes {
                for view in &scene.views {
                    let Some(own) = view.workload1_intersect_ms() else {
                        continue;
                    };
                    let engine = |e: Engine| view.engines.iter().find(|r| r.engine == e);
                    let rate = |m: &Measurement| m.intersect_ms().map(|t| mrays(view.rays, t));
                    let cell = |v: Option<f64>, digits: usize| {
                        v.map_or("–".into(), |v| format!("{v:.digits$}"))
                    };
                    let single = engine(Engine::EmbreeSingle);
                    let packet = engine(Engine::EmbreePacket);
                    let single_rate = single.and_then(|e| rate(&e.unfused));
                    let packet_rate = packet.and_then(|e| rate(&e.unfused));
                    let own_rate = mrays(view.rays, own);
                    let hits = |e: Option<&super::EngineResult>| {
                        e.map_or("–".into(), |e| {
                            let one_sided = match (e.one_sided, e.one_sided_at_border) {
                                (0, _) => String::new(),
                                (n, b) if n == b => format!(" ({n} one-sided, all at a border)"),
                                (n, b) => format!(" ({n} one-sided, {b} at a border)"),
                            };
                            format!(
                                "{} / {}{one_sided}{}",
                                e.hits_dpp,
                                e.hits_engine,
                                if e.agrees() { "" } else { " ✗" }
                            )
                        })
                    };
                    let same = |e: Option<&super::EngineResult>| {
                        e.map_or("–".into(), |e| {
                            if e.ties > 0.0 {
                                format!("{:.3}% (+{:.3}%)", 100.0 * e.same_triangle, 100.0 * e.ties)
                            } else {
                                format!("{:.3}%", 100.0 * e.same_triangle)
                            }
                        })
                    };
                    let _ = writeln!(
                        md,
                        "| {} | {} | {:.2} | {} | {} | {} | {} | {} | {} | {} / {} |",
                        scene.name,
                        view.view,
                        own_rate,
                        cell(single_rate, 2),
                        cell(packet_rate, 2),
                        cell(single_rate.map(|r| own_rate / r), 2),
                        cell(packet_rate.map(|r| own_rate / r), 2),
                        hits(single),
                        hits(packet),
                        same(single),
                        same(packet),
                    );
                }
            }
            md.push('\n');
        }

        if self.has_workload(2) || self.has_workload(3) {
            let _ = writeln!(md, "## WORKLOAD2 and WORKLOAD3, frames per second\n");
            let _ = writeln!(md, "Beyond the traversal: the fused frame's wall time outside `map<intersect>` and `map<occluded>` (each stage's share of them, from its op split), in ns per pixel (CPU only). Last column: the fused frame over WORKLOAD1's `map<intersect>` time on the same rays (when WORKLOAD1 ran too).\n");
            let _ = writeln!(md, "| scene | view | workload | fused fps | unfused fps | fused ms | unfused ms | fusion gain | beyond the traversal, ns/pixel | fused / W1 intersect |");
            let _ = writeln!(
                md,
                "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
            );
            for scene in &self.scenes {
                for view in &scene.views {
                    let own = view.workload1_intersect_ms();
                    for w in view.workloads.iter().filter(|w| w.workload != 1) {
                        let over_intersect = own
                            .map(|own| format!("{:.2}×", w.fused.mean_ms() / own))
                            .unwrap_or_else(|| "–".into());
                        let _ = writeln!(
                            md,
                            "| {} | {} | WORKLOAD{} | {:.3} | {:.3} | {:.1} | {:.1} | {:.2}× | {} | {} |",
                            scene.name,
                            view.view,
                            w.workload,
                            w.fused.fps(),
                            w.unfused.fps(),
                            w.fused.mean_ms(),
                            w.unfused.mean_ms(),
                            w.fusion_gain(),
                            beyond_traversal(&w.fused, view.rays),
                            over_intersect
                        );
                    }
                }
            }
            md.push('\n');
        }

        for workload in [2, 3] {
            if self.has_engine_frames(workload) {
                self.write_engine_frames(&mut md, workload);
            }
        }
        self.write_engines_in_turn(&mut md);
        self.write_side_by_side(&mut md);

        let _ = writeln!(
            md,
            "## Time per stage, ms per frame (mean over the views)\n"
        );
        for scene in &self.scenes {
            let workloads: Vec<u32> = scene
                .views
                .first()
                .map(|v| v.workloads.iter().map(|w| w.workload).collect())
                .unwrap_or_default();
            for workload in workloads {
                for fused in [true, false] {
                    let measurements: Vec<&Measurement> = scene
                        .views
                        .iter()
                        .flat_map(|v| v.workloads.iter().filter(|w| w.workload == workload))
                        .map(|w| if fused { &w.fused } else { &w.unfused })
                        .collect();
                    let Some(first) = measurements.first() else {
                        continue;
                    };
                    let views = measurements.len() as f64;
                    let frame = measurements.iter().map(|m| m.mean_ms()).sum::<f64>() / views;
                    // A stage's share is of the frame its time comes from: on the
                    // GPU, the profiled runs'.
                    let (profiled, whole) = if self.gpu.is_some() {
                        let profiled = measurements
                            .iter()
                            .map(|m| mean(&m.profiled_frames_ms))
                            .sum::<f64>()
                            / views;
                        (format!("; {profiled:.1} ms profiled"), profiled)
                    } else {
                        (String::new(), frame)
                    };
                    let _ = writeln!(
                        md,
                        "{} WORKLOAD{workload}, {} ({} stages, frame {frame:.1} ms{profiled}):\n",
                        scene.name,
                        if fused { "fused" } else { "unfused" },
                        first.stages.len()
                    );
                    let _ = writeln!(md, "| stage | ops | ms | share |");
                    let _ = writeln!(md, "| ---: | --- | ---: | ---: |");
                    for (i, stage) in first.stages.iter().enumerate() {
                        let mean = measurements
                            .iter()
                            .filter_map(|m| m.stages.get(i))
                            .map(|s| s.ms)
                            .sum::<f64>()
                            / views;
                        let _ = writeln!(
                            md,
                            "| {} | `{}` | {:.2} | {:.1}% |",
                            stage.stage,
                            stage.label,
                            mean,
                            100.0 * mean / whole
                        );
                    }
                    md.push('\n');
                    if fused {
                        write_op_split(&mut md, &measurements, views);
                    }
                }
            }
        }
        md
    }

    pub fn json(&self) -> Value {
        let report_width = self.size.0.max(1);
        // JSON has no infinity: a miss's distance is null.
        let finite = |t: f32| if t.is_finite() { json!(t) } else { Value::Null };
        let measurement = |m: &Measurement, rays: Option<u64>| {
            let mut value = json!({
                "frames_ms": m.frames_ms,
                "first_frame_ms": m.first_frame_ms,
                "mean_frame_ms": m.mean_ms(),
                "fps": m.fps(),
                "stages": m.stages.iter().map(|s| json!({
                    "stage": s.stage,
                    "ops": s.label,
                    "ms": s.ms,
                    "op_thread_ms": s.ops.iter().map(|op| json!({
                        "op": op.label,
                        "thread_ms": ms(op.thread_time),
                    })).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
            });
            if self.gpu.is_some() {
                value["profiled_frames_ms"] = json!(m.profiled_frames_ms);
            }
            if let Some(rays) = rays {
                value["frame_mrays_per_s"] = json!(mrays(rays, m.mean_ms()));
                if let Some(t) = m.intersect_ms() {
                    value["intersect_ms"] = json!(t);
                    value["intersect_mrays_per_s"] = json!(mrays(rays, t));
                }
            }
            value
        };
        let scenes: Vec<Value> = self
            .scenes
            .iter()
            .map(|scene| {
                let views: Vec<Value> = scene
                    .views
                    .iter()
                    .map(|view| {
                        let rays = |workload: u32| (workload == 1).then_some(view.rays);
                        let own = view.workload1_intersect_ms();
                        json!({
                            "view": view.view,
                            "primary_rays": view.rays,
                            "workloads": view.workloads.iter().map(|w| json!({
                                "workload": w.workload,
                                "fused": measurement(&w.fused, rays(w.workload)),
                                "unfused": measurement(&w.unfused, rays(w.workload)),
                                "fusion_gain": w.fusion_gain(),
                                "fused_over_workload1_intersect": own
                                    .filter(|_| w.workload != 1)
                                    .map(|own| w.fused.mean_ms() / own),
                                "beyond_traversal_ns_per_pixel": w.fused.beyond_traversal_ns_per_pixel(view.rays),
                            })).collect::<Vec<_>>(),
                            "engines": view.engines.iter().map(|e| {
                                let rate = e.unfused.intersect_ms().map(|t| mrays(view.rays, t));
                                json!({
                                    "engine": e.engine.name(),
                                    "fused": measurement(&e.fused, Some(view.rays)),
                                    "unfused": measurement(&e.unfused, Some(view.rays)),
                                    "dpp_over_engine": match (own, rate) {
                                        (Some(own), Some(rate)) => json!(mrays(view.rays, own) / rate),
                                        _ => Value::Null,
                                    },
                                    "hits_dpp": e.hits_dpp,
                                    "hits_engine": e.hits_engine,
                                    "same_triangle": e.same_triangle,
                                    "ties": e.ties,
                                    "one_sided": e.one_sided,
                                    "one_sided_at_border": e.one_sided_at_border,
                                    "hit_mismatches": e.mismatches.iter().map(|&(pixel, dpp_prim, dpp_t, prim, t)| json!({
                                        "x": pixel % report_width,
                                        "y": pixel / report_width,
                                        "dpp_prim": dpp_prim,
                                        "dpp_t": finite(dpp_t),
                                        "engine_prim": prim,
                                        "engine_t": finite(t),
                                    })).collect::<Vec<_>>(),
                                    "agree": e.agrees(),
                                })
                            }).collect::<Vec<_>>(),
                            "engine_frames": view.engine_frames.iter().map(|e| {
                                let own = view.workloads.iter().find(|w| w.workload == e.workload);
                                let over_intersect = view
                                    .engine_workload1_intersect_ms(e.engine)
                                    .map(|intersect| e.fused.mean_ms() / intersect);
                                json!({
                                    "workload": e.workload,
                                    "engine": e.engine.name(),
                                    "fused": measurement(&e.fused, None),
                                    "engine_over_dpp": own.map(|w| e.fused.mean_ms() / w.fused.mean_ms()),
                                    "intersect_thread_ms": e.fused.map_thread_ms("intersect"),
                                    "occluded_thread_ms": e.fused.map_thread_ms("occluded"),
                                    "beyond_traversal_ns_per_pixel": e.fused.beyond_traversal_ns_per_pixel(view.rays),
                                    "fused_over_workload1_intersect": over_intersect,
                                })
                            }).collect::<Vec<_>>(),
                            "side_by_side": view.side_by_side.as_ref().map(side_by_side_json),
                            "engines_in_turn": view.engines_in_turn.iter().map(side_by_side_json).collect::<Vec<_>>(),
                        })
                    })
                    .collect();
                json!({
                    "name": scene.name,
                    "triangles": scene.triangles,
                    "load_ms": scene.load_ms,
                    "normals_ms": scene.normals_ms,
                    "bvh_build_ms": scene.bvh_ms,
                    "embree_build_ms": scene.embree_build_ms,
                    "embree_high_build_ms": scene.embree_high_build_ms,
                    "views": views,
                })
            })
            .collect();
        let mut report = json!({
            "backend": if self.gpu.is_some() { "gpu" } else { "cpu" },
            "cpu": self.cpu,
            "threads": self.threads,
            "bvh": format!("{:?}", self.bvh).to_lowercase(),
            "size": [self.size.0, self.size.1],
            "warmup_rounds": self.warmup,
            "measured_rounds": self.rounds,
            "workload2_compile_ms": self.workload2_compile_ms,
            // The name `--embree-test` takes.
            "embree_test": self
                .embree_test
                .and_then(|test| clap::ValueEnum::to_possible_value(&test))
                .map(|value| value.get_name().to_string()),
            "dpp_version": env!("CARGO_PKG_VERSION"),
            "scenes": scenes,
        });
        if let Some(gpu) = &self.gpu {
            report["adapter"] = json!({
                "name": gpu.name,
                "backend": gpu.api,
                "device_type": gpu.device_type,
                "driver": gpu.driver,
                "driver_info": gpu.driver_info,
            });
            report["stage_timing"] = json!(gpu.stage_timing());
        }
        report
    }
}

/// Plans measured in turn, a row per pair: each's minimum and median, and
/// the other's over the own one's.
fn write_in_turn_table(md: &mut String, rows: &[(&SceneResult, &ViewResult, &SideBySide)]) {
    let _ = writeln!(
        md,
        "| scene | view | workload | measured | own | min | median | other | min | median | other / own: median of the rounds | of the minima |"
    );
    let _ = writeln!(
        md,
        "| --- | --- | --- | --- | --- | ---: | ---: | --- | ---: | ---: | ---: | ---: |"
    );
    for (scene, view, pair) in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {} | {:.1} | {:.1} | {:.3} | {:.3} |",
            scene.name,
            view.view,
            pair.workload,
            pair.quantity.name(),
            pair.own,
            minimum(&pair.own_ms),
            median(&pair.own_ms),
            pair.versus,
            minimum(&pair.versus_ms),
            median(&pair.versus_ms),
            median(&pair.ratios()),
            minimum(&pair.versus_ms) / minimum(&pair.own_ms)
        );
    }
    md.push('\n');
}

/// Two plans measured in turn: each round's `quantity`, ms, and the other's
/// over the own one's.
fn side_by_side_json(pair: &SideBySide) -> Value {
    json!({
        "workload": pair.workload,
        "own": pair.own,
        "versus": pair.versus,
        "measured": pair.quantity.name(),
        "own_ms": pair.own_ms,
        "versus_ms": pair.versus_ms,
        "ratios": pair.ratios(),
        "median_ratio": median(&pair.ratios()),
    })
}

/// The op split of each fused stage of more than one op (CPU backend): the
/// time its chunks spent in each op, summed over threads, as a mean over the
/// views; the op's share of the stage's op time; and that share of the stage's
/// wall time, which is what the op costs the frame.
fn write_op_split(md: &mut String, measurements: &[&Measurement], views: f64) {
    let Some(first) = measurements.first() else {
        return;
    };
    for (index, stage) in first.stages.iter().enumerate() {
        let stages: Vec<_> = measurements
            .iter()
            .filter_map(|m| m.stages.get(index))
            .collect();
        let mean_of = |value: &dyn Fn(&super::StageTime) -> f64| {
            stages.iter().map(|s| value(s)).sum::<f64>() / views
        };
        let stage_ms = mean_of(&|s| s.ms);
        let mut mean_ops = stage.ops.clone();
        for (position, op) in mean_ops.iter_mut().enumerate() {
            let seconds = mean_of(&|s| {
                s.ops
                    .get(position)
                    .map_or(0.0, |o| o.thread_time.as_secs_f64())
            });
            op.thread_time = std::time::Duration::from_secs_f64(seconds);
        }
        let shares = listed_op_shares(&mean_ops);
        if shares.is_empty() {
            continue;
        }
        let _ = writeln!(
            md,
            "Inside stage {}: each op's time summed over the threads, its share of the stage's op time, and that share of the stage's {stage_ms:.1} ms:\n",
            stage.stage
        );
        let _ = writeln!(md, "| op | thread ms | share | ms of the stage |");
        let _ = writeln!(md, "| --- | ---: | ---: | ---: |");
        for (op, share) in shares {
            let _ = writeln!(
                md,
                "| `{}` | {:.2} | {:.1}% | {:.1} |",
                op.label,
                ms(op.thread_time),
                100.0 * share,
                share * stage_ms
            );
        }
        md.push('\n');
    }
}
