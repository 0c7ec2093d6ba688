//! Image finishing for `dpp run`: a transparent background (from the
//! pipeline's `alpha` output) and a colour bar with its labelled range.

use dpp_tracer::shading::{linear_to_srgb, srgb_to_linear};
use font8x8::UnicodeFonts;
use glam::Vec3;

/// An RGBA image being finished, 8 bits per channel, row-major.
pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<[u8; 4]>,
}

impl Canvas {
    /// Display colours (already sRGB-encoded) with full opacity.
    pub fn from_display(width: u32, height: u32, colours: &[Vec3]) -> Canvas {
        let rgba = colours.iter().map(|c| rgba_of(*c, 1.0)).collect();
        Canvas {
            width,
            height,
            rgba,
        }
    }

    /// Display colours over `background` with coverage `alpha`: the pixels become
    /// the foreground alone (un-blended in linear light) with that opacity.
    pub fn transparent(
        width: u32,
        height: u32,
        colours: &[Vec3],
        alpha: &[f32],
        background: Vec3,
    ) -> Canvas {
        let background = srgb_to_linear(background);
        let rgba = colours
            .iter()
            .zip(alpha)
            .map(|(colour, &a)| {
                if a <= 0.0 {
                    return [0, 0, 0, 0];
                }
                let linear = srgb_to_linear(*colour);
                let foreground =
                    ((linear - (1.0 - a) * background) / a).clamp(Vec3::ZERO, Vec3::ONE);
                rgba_of(linear_to_srgb(foreground), a)
            })
            .collect();
        Canvas {
            width,
            height,
            rgba,
        }
    }

    fn put(&mut self, x: u32, y: u32, colour: [u8; 4]) {
        if x < self.width && y < self.height {
            self.rgba[(y * self.width + x) as usize] = colour;
        }
    }

    /// A vertical bar of `lut` (display colours, low to high) at the right edge,
    /// with `range`'s ends and middle written beside it.
    pub fn draw_colorbar(&mut self, lut: &[Vec3], range: [f32; 2]) {
        let scale = (self.height / 360).max(1);
        let bar_width = (self.width / 40).max(6);
        let bar_height = self.height * 3 / 5;
        let labels: Vec<String> = [range[1], 0.5 * (range[0] + range[1]), range[0]]
            .iter()
            .map(|v| label(*v))
            .collect();
        let text_width = labels.iter().map(|l| l.len() as u32).max().unwrap_or(0) * 8 * scale;
        let margin = 4 * scale;
        let Some(left) = self.width.checked_sub(bar_width + text_width + 3 * margin) else {
            return; // too small an image for a bar: leave it as it is
        };
        let top = (self.height - bar_height) / 2;
        let white = [255, 255, 255, 255];
        for row in 0..bar_height {
            // The top of the bar is the high end of the range.
            let t = 1.0 - row as f32 / (bar_height - 1).max(1) as f32;
            let index = ((t * (lut.len() - 1) as f32).round() as usize).min(lut.len() - 1);
            let colour = rgba_of(lut[index], 1.0);
            for column in 0..bar_width {
                self.put(left + column, top + row, colour);
            }
        }
        for (column, row) in (0..bar_width)
            .flat_map(|c| [(c, 0), (c, bar_height)])
            .chain((0..=bar_height).flat_map(|r| [(0, r), (bar_width, r)]))
        {
            self.put(left + column, top + row, white);
        }
        let text_left = left + bar_width + margin;
        let rows = [top, top + bar_height / 2, top + bar_height];
        for (text, row) in labels.iter().zip(rows) {
            self.draw_text(text, text_left, row.saturating_sub(4 * scale), scale);
        }
    }

    /// White 8×8 glyphs scaled by `scale`, on a dark outline so they read on any background.
    fn draw_text(&mut self, text: &str, left: u32, top: u32, scale: u32) {
        let glyph_pixels = |c: char| {
            let rows = font8x8::BASIC_FONTS.get(c).unwrap_or([0; 8]);
            (0..8u32).flat_map(move |y| {
                (0..8u32)
                    .filter(move |x| rows[y as usize] >> x & 1 == 1)
                    .map(move |x| (x, y))
            })
        };
        for pass in [[20, 20, 20, 255], [255, 255, 255, 255]] {
            let outline = pass[0] < 128;
            for (i, c) in text.chars().enumerate() {
                let origin = left + i as u32 * 8 * scale;
                for (x, y) in glyph_pixels(c) {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (px, py) = (origin + x * scale + dx, top + y * scale + dy);
                            if outline {
                                for (ox, oy) in [(0, 1), (2, 1), (1, 0), (1, 2)] {
                                    self.put(
                                        (px + ox).saturating_sub(1),
                                        (py + oy).saturating_sub(1),
                                        pass,
                                    );
                                }
                            } else {
                                self.put(px, py, pass);
                            }
                        }
                    }
                }
            }
        }
    }
}

fn rgba_of(colour: Vec3, alpha: f32) -> [u8; 4] {
    let byte = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [byte(colour.x), byte(colour.y), byte(colour.z), byte(alpha)]
}

/// A short, readable number: `0.25`, `128`, `-1.5e-3`.
fn label(value: f32) -> String {
    let magnitude = value.abs();
    if magnitude != 0.0 && !(0.01..10000.0).contains(&magnitude) {
        format!("{value:.1e}")
    } else if magnitude >= 100.0 {
        format!("{value:.0}")
    } else {
        let text = format!("{value:.2}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_short_and_exact_enough() {
        for (value, text) in [
            (0.25, "0.25"),
            (128.0, "128"),
            (-1.5, "-1.5"),
            (0.0, "0"),
            (0.0015, "1.5e-3"),
            (25000.0, "2.5e4"),
        ] {
            assert_eq!(label(value), text);
        }
    }

    #[test]
    fn transparency_recovers_the_foreground() {
        let background = Vec3::splat(0.1);
        let foreground = Vec3::new(0.8, 0.4, 0.2);
        // A half-covered pixel: half foreground, half background, in linear light.
        let blended =
            linear_to_srgb(0.5 * srgb_to_linear(foreground) + 0.5 * srgb_to_linear(background));
        let canvas = Canvas::transparent(2, 1, &[blended, background], &[0.5, 0.0], background);
        let [r, g, b, a] = canvas.rgba[0];
        let expected = rgba_of(foreground, 0.5);
        for (got, want) in [r, g, b, a].iter().zip(expected) {
            assert!(
                (*got as i32 - want as i32).abs() <= 1,
                "{:?} vs {expected:?}",
                canvas.rgba[0]
            );
        }
        assert_eq!(canvas.rgba[1], [0, 0, 0, 0]);
    }

    #[test]
    fn the_colour_bar_shows_the_map_high_end_on_top() {
        let lut: Vec<Vec3> = (0..256)
            .map(|i| Vec3::new(i as f32 / 255.0, 0.0, 1.0 - i as f32 / 255.0))
            .collect();
        let mut canvas = Canvas::from_display(200, 100, &vec![Vec3::ZERO; 200 * 100]);
        canvas.draw_colorbar(&lut, [0.0, 1.0]);
        // The bar's colours have no green; take the column with most of them.
        let bar_pixels = |x: usize| -> Vec<[u8; 4]> {
            (0..100)
                .map(|y| canvas.rgba[y * 200 + x])
                .filter(|p| p[1] == 0 && (p[0] > 0 || p[2] > 0))
                .collect()
        };
        let column = (0..200).map(bar_pixels).max_by_key(|c| c.len()).unwrap();
        assert!(column.len() > 40, "the bar is missing");
        assert!(
            column[0][0] > column[column.len() - 1][0],
            "high values (red) belong on top"
        );
        let text = canvas
            .rgba
            .iter()
            .filter(|p| **p == [255, 255, 255, 255])
            .count();
        assert!(text > 50, "labels and outline are drawn");
    }
}
