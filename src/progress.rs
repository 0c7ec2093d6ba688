//! `dpp run`'s progress on a terminal: one line per phase of the work (load,
//! normals, BVH, the frame's stages, writing each output), so that a 12.5M
//! triangle mesh or a 144M-pixel image is not many silent seconds. While a
//! phase runs a spinner shows it and its time (the frame's line names the
//! stage that is running); when it ends it leaves `PHASE: 1.23 s` above.
//! Nothing at all is drawn when stderr is not a terminal, or with `--quiet`.

use dpp_runtime::interpret::StageStart;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub struct Progress {
    bar: ProgressBar,
    /// Whether the spinner turns on its own yet (from the first phase on).
    ticking: AtomicBool,
    /// The phase running, and since when.
    phase: Mutex<Option<(String, Instant)>>,
}

impl Progress {
    /// Progress on stderr if it is a terminal and `quiet` is off; else none.
    pub fn on_terminal(quiet: bool) -> Progress {
        Progress::new(!quiet && std::io::stderr().is_terminal())
    }

    fn new(shown: bool) -> Progress {
        let bar = if shown {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            // `wide_msg`: a long stage label is cut at the terminal's width.
            if let Ok(style) = ProgressStyle::with_template("{spinner} {elapsed:>3} {wide_msg}") {
                bar.set_style(style);
            }
            bar
        } else {
            ProgressBar::hidden()
        };
        Progress {
            bar,
            ticking: AtomicBool::new(false),
            phase: Mutex::new(None),
        }
    }

    /// Ends the phase running (leaving its line) and starts `name`.
    pub fn phase(&self, name: impl Into<String>) {
        let name = name.into();
        let mut phase = self.phase.lock().unwrap_or_else(|e| e.into_inner());
        self.end(&mut phase);
        self.bar.reset_elapsed();
        self.bar.set_message(name.clone());
        *phase = Some((name, Instant::now()));
        if !self.bar.is_hidden() && !self.ticking.swap(true, Ordering::Relaxed) {
            // A single long phase (a BVH build) still shows its time passing.
            self.bar.enable_steady_tick(Duration::from_millis(120));
        }
    }

    /// Runs `print` with the spinner taken away, so that what it prints on
    /// the same terminal (stdout's messages) is not drawn over.
    pub fn suspend<R>(&self, print: impl FnOnce() -> R) -> R {
        self.bar.suspend(print)
    }

    /// A stage of the frame is about to run: the phase's line names it.
    pub fn stage(&self, stage: &StageStart<'_>) {
        if self.bar.is_hidden() {
            return;
        }
        let phase = self.phase.lock().unwrap_or_else(|e| e.into_inner());
        let name = phase.as_ref().map_or("", |(name, _)| name.as_str());
        let run = if stage.run > 1 {
            format!(", run {}", stage.run)
        } else {
            String::new()
        };
        self.bar.set_message(format!(
            "{name}: stage {}/{}{run} [{}]",
            stage.stage, stage.stages, stage.label
        ));
    }

    /// Ends the last phase, leaving its line, and takes the spinner away.
    pub fn finish(&self) {
        let mut phase = self.phase.lock().unwrap_or_else(|e| e.into_inner());
        self.end(&mut phase);
        self.bar.finish_and_clear();
    }
}

impl Progress {
    /// Leaves the line of the phase that ends.
    fn end(&self, phase: &mut Option<(String, Instant)>) {
        if let Some((ended, start)) = phase.take() {
            self.bar
                .println(format!("{ended}: {:.2} s", start.elapsed().as_secs_f64()));
        }
    }
}

impl Drop for Progress {
    /// A run that fails takes the spinner away before its error is printed.
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
