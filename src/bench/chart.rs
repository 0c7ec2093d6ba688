//! `dpp bench --chart`: a grouped bar chart as a PNG. plotters draws the bars
//! and the grid into an RGB buffer (its bitmap backend, no font backend: the
//! build needs no system fonts); the labels are drawn with the public-domain
//! 8×8 bitmap font the colour bar uses, then the buffer is written with `image`.

use super::report::Report;
use super::Engine;
use font8x8::UnicodeFonts;
use plotters::prelude::*;
use std::path::Path;

/// Bars of one group: a label (two lines) and a value per series.
struct Group {
    label: [String; 2],
    values: Vec<Option<f64>>,
}

struct Chart {
    title: String,
    unit: String,
    series: Vec<String>,
    groups: Vec<Group>,
}

const COLOURS: [RGBColor; 4] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xd6, 0x27, 0x28),
];
const TEXT: [u8; 3] = [20, 20, 20];

fn mrays(rays: u64, ms: f64) -> f64 {
    rays as f64 / (ms * 1e3)
}

/// What ran the plans, for the title: `2 threads` on the CPU, `GPU <adapter>`.
fn on(report: &Report) -> String {
    match &report.gpu {
        None => format!("{} threads", report.threads),
        Some(gpu) => format!("GPU {} ({})", gpu.name, gpu.api),
    }
}

/// WORKLOAD1's rates when it ran (per engine, or the stage and the frame), else
/// the frame rates of the other workloads, fused and unfused.
fn chart_of(report: &Report) -> Chart {
    let engines = report
        .scenes
        .iter()
        .flat_map(|s| &s.views)
        .any(|v| !v.engines.is_empty());
    let has_w1 = report
        .scenes
        .iter()
        .flat_map(|s| &s.views)
        .any(|v| v.workloads.iter().any(|w| w.workload == 1));
    let mut groups = Vec::new();
    if has_w1 {
        let series: Vec<String> = if engines {
            ["dpp", "Embree single", "Embree packet"]
                .map(String::from)
                .to_vec()
        } else {
            ["map<intersect>", "frame, fused"]
                .map(String::from)
                .to_vec()
        };
        for scene in &report.scenes {
            for view in &scene.views {
                let Some(w) = view.workloads.iter().find(|w| w.workload == 1) else {
                    continue;
                };
                let own = w.unfused.intersect_ms().map(|t| mrays(view.rays, t));
                let values = if engines {
                    let engine = |e: Engine| {
                        view.engines
                            .iter()
                            .find(|r| r.engine == e)
                            .and_then(|r| r.unfused.intersect_ms())
                            .map(|t| mrays(view.rays, t))
                    };
                    vec![
                        own,
                        engine(Engine::EmbreeSingle),
                        engine(Engine::EmbreePacket),
                    ]
                } else {
                    vec![own, Some(mrays(view.rays, w.fused.mean_ms()))]
                };
                groups.push(Group {
                    label: [scene.name.clone(), view.view.clone()],
                    values,
                });
            }
        }
        Chart {
            title: format!(
                "WORKLOAD1, {}x{}, {}",
                report.size.0,
                report.size.1,
                on(report)
            ),
            unit: "Mrays/s".into(),
            series,
            groups,
        }
    } else {
        for scene in &report.scenes {
            for view in &scene.views {
                for w in &view.workloads {
                    groups.push(Group {
                        label: [scene.name.clone(), format!("{} W{}", view.view, w.workload)],
                        values: vec![Some(w.fused.fps()), Some(w.unfused.fps())],
                    });
                }
            }
        }
        Chart {
            title: format!(
                "frames per second, {}x{}, {}",
                report.size.0,
                report.size.1,
                on(report)
            ),
            unit: "frames/s".into(),
            series: vec!["fused".into(), "unfused".into()],
            groups,
        }
    }
}

pub fn draw(report: &Report, path: &Path) -> Result<(), String> {
    let chart = chart_of(report);
    let group_width = 40 + 36 * chart.series.len() as u32;
    // Wide enough for the bars and for the title (16 pixels a character, after
    // the left margin), so that a long adapter name is not cut off.
    let title_width = 70 + 16 * chart.title.chars().count() as u32 + 20;
    let (width, height) = (
        (120 + group_width * chart.groups.len() as u32)
            .max(640)
            .max(title_width),
        480u32,
    );
    let mut buffer = vec![255u8; (width * height * 3) as usize];
    let max = chart
        .groups
        .iter()
        .flat_map(|g| g.values.iter().flatten())
        .fold(0.0f64, |a, &b| a.max(b));
    let top = nice_ceiling(max * 1.15);
    let groups = chart.groups.len().max(1) as f64;
    let (left, right, plot_top, bottom) = (70i32, 20i32, 60i32, 60i32);
    let mut labels: Vec<(i32, i32, String, u32, bool)> = Vec::new();
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        let error = |e: DrawingAreaErrorKind<_>| format!("drawing the chart failed: {e:?}");
        let mut area = ChartBuilder::on(&root)
            .margin_left(left as u32)
            .margin_right(right as u32)
            .margin_top(plot_top as u32)
            .margin_bottom(bottom as u32)
            .build_cartesian_2d(0.0..groups, 0.0..top)
            .map_err(error)?;
        // Horizontal grid lines and their values.
        for i in 0..=5 {
            let y = top * f64::from(i) / 5.0;
            area.draw_series(std::iter::once(PathElement::new(
                vec![(0.0, y), (groups, y)],
                RGBColor(220, 220, 220).stroke_width(1),
            )))
            .map_err(error)?;
            let (px, py) = area.backend_coord(&(0.0, y));
            let decimals = if top >= 50.0 {
                0
            } else if top >= 5.0 {
                1
            } else {
                2
            };
            labels.push((px - 6, py - 4, format!("{y:.decimals$}"), 1, true));
        }
        // The bars.
        let n = chart.series.len() as f64;
        let bar = 0.8 / n;
        for (g, group) in chart.groups.iter().enumerate() {
            for (s, value) in group.values.iter().enumerate() {
                let Some(value) = *value else { continue };
                let x0 = g as f64 + 0.1 + bar * s as f64;
                area.draw_series(std::iter::once(Rectangle::new(
                    [(x0, 0.0), (x0 + bar * 0.9, value)],
                    COLOURS[s % COLOURS.len()].filled(),
                )))
                .map_err(error)?;
                let (px, py) = area.backend_coord(&(x0 + bar * 0.45, value));
                let text = format_value(value);
                labels.push((px - 4 * text.len() as i32, py - 11, text, 1, false));
            }
            let (px, py) = area.backend_coord(&(g as f64 + 0.5, 0.0));
            for (line, text) in group.label.iter().enumerate() {
                let text = shorten(text, (group_width / 8) as usize);
                labels.push((
                    px - 4 * text.len() as i32,
                    py + 8 + 12 * line as i32,
                    text,
                    1,
                    false,
                ));
            }
        }
        // The axes.
        area.draw_series(std::iter::once(PathElement::new(
            vec![(0.0, top), (0.0, 0.0), (groups, 0.0)],
            BLACK.stroke_width(1),
        )))
        .map_err(error)?;
        // The legend's swatches.
        let mut x = left;
        for (s, name) in chart.series.iter().enumerate() {
            root.draw(&Rectangle::new(
                [(x, 36), (x + 12, 48)],
                COLOURS[s % COLOURS.len()].filled(),
            ))
            .map_err(error)?;
            labels.push((x + 18, 38, name.clone(), 1, false));
            x += 18 + 8 * name.len() as i32 + 24;
        }
        root.present().map_err(error)?;
    }
    let mut canvas = Canvas {
        width,
        height,
        rgb: &mut buffer,
    };
    canvas.text(left, 10, &chart.title, 2);
    canvas.text(8, plot_top - 20, &chart.unit, 1);
    for (x, y, text, scale, right_aligned) in labels {
        let x = if right_aligned {
            x - 8 * scale as i32 * text.chars().count() as i32
        } else {
            x
        };
        canvas.text(x, y, &text, scale);
    }
    image::RgbImage::from_raw(width, height, buffer)
        .ok_or("the chart buffer has the wrong size")?
        .save(path)
        .map_err(|e| e.to_string())
}

/// A round number at or above `value` (1, 2 or 5 times a power of ten).
fn nice_ceiling(value: f64) -> f64 {
    if !value.is_finite() || value <= 0.0 {
        return 1.0;
    }
    let power = 10f64.powf(value.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|&v| v >= value)
        .unwrap_or(10.0 * power)
}

fn format_value(value: f64) -> String {
    if value >= 100.0 {
        format!("{value:.0}")
    } else if value >= 10.0 {
        format!("{value:.1}")
    } else {
        format!("{value:.2}")
    }
}

fn shorten(text: &str, max: usize) -> String {
    if text.chars().count() <= max {
        text.to_string()
    } else {
        let kept: String = text.chars().take(max.saturating_sub(1)).collect();
        format!("{kept}~")
    }
}

/// Text drawn into an RGB buffer with the 8×8 font.
struct Canvas<'a> {
    width: u32,
    height: u32,
    rgb: &'a mut [u8],
}

impl Canvas<'_> {
    fn text(&mut self, x: i32, y: i32, text: &str, scale: u32) {
        let step = 8 * scale as i32;
        for (i, c) in text.chars().enumerate() {
            let glyph = font8x8::BASIC_FONTS
                .get(c)
                .or_else(|| font8x8::BASIC_FONTS.get('?'))
                .unwrap_or([0; 8]);
            for (row, bits) in glyph.iter().enumerate() {
                for column in 0..8 {
                    if bits >> column & 1 == 0 {
                        continue;
                    }
                    for dy in 0..scale as i32 {
                        for dx in 0..scale as i32 {
                            self.put(
                                x + i as i32 * step + column * scale as i32 + dx,
                                y + row as i32 * scale as i32 + dy,
                            );
                        }
                    }
                }
            }
        }
    }

    fn put(&mut self, x: i32, y: i32) {
        if x < 0 || y < 0 || x >= self.width as i32 || y >= self.height as i32 {
            return;
        }
        let at = 3 * (y as usize * self.width as usize + x as usize);
        self.rgb[at..at + 3].copy_from_slice(&TEXT);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_ceilings() {
        assert_eq!(nice_ceiling(0.0), 1.0);
        assert_eq!(nice_ceiling(7.3), 10.0);
        assert_eq!(nice_ceiling(11.0), 20.0);
        assert_eq!(nice_ceiling(0.42), 0.5);
        assert_eq!(nice_ceiling(f64::NAN), 1.0);
    }
}
