//! Small PNG charts for the reports: line plots with numbered axes and a legend, and a
//! top-down map, drawn into an RGB buffer with a built-in 3 × 5 pixel font.

use std::path::Path;

use crate::icr2d::write_png;

/// An RGB colour.
pub type Rgb = [u8; 3];

/// Colours for successive series.
pub const PALETTE: [Rgb; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];

/// An RGB image.
#[derive(Debug, Clone)]
pub struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

/// Glyphs of the 3 × 5 font: five rows of three bits, the top row in the high bits.
fn glyph(c: char) -> u16 {
    let rows: [u8; 5] = match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        '-' => [0, 0, 7, 0, 0],
        ':' => [0, 2, 0, 2, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [2, 4, 4, 4, 2],
        ')' => [2, 1, 1, 1, 2],
        '%' => [5, 1, 2, 4, 5],
        '=' => [0, 7, 0, 7, 0],
        '+' => [0, 2, 7, 2, 0],
        _ => [0; 5],
    };
    rows.iter()
        .fold(0u16, |acc, &r| (acc << 3) | u16::from(r & 7))
}

impl Canvas {
    /// A white canvas.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            rgb: vec![255; width * height * 3],
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Sets a pixel; pixels off the canvas are ignored.
    pub fn set(&mut self, x: i64, y: i64, c: Rgb) {
        let (Ok(x), Ok(y)) = (usize::try_from(x), usize::try_from(y)) else {
            return;
        };
        if x < self.width && y < self.height {
            let i = 3 * (y * self.width + x);
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// The colour of a pixel (white off the canvas).
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        if x < self.width && y < self.height {
            let i = 3 * (y * self.width + x);
            [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
        } else {
            [255; 3]
        }
    }

    /// A line from (x0, y0) to (x1, y1) (Bresenham), `thick` pixels wide.
    pub fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: Rgb, thick: i64) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        let r = (thick - 1) / 2;
        loop {
            for ox in -r..=thick - 1 - r {
                for oy in -r..=thick - 1 - r {
                    self.set(x + ox, y + oy, c);
                }
            }
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// A filled rectangle.
    pub fn fill(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: Rgb) {
        for y in y0.min(y1)..=y0.max(y1) {
            for x in x0.min(x1)..=x0.max(x1) {
                self.set(x, y, c);
            }
        }
    }

    /// Text with its top-left corner at (x, y), each font pixel `scale` pixels wide.
    pub fn text(&mut self, x: i64, y: i64, s: &str, c: Rgb, scale: i64) {
        for (i, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            // Text lengths are small.
            #[allow(clippy::cast_possible_wrap)]
            let ox = x + i as i64 * 4 * scale;
            for row in 0..5i64 {
                for col in 0..3i64 {
                    if g >> ((4 - row) * 3 + (2 - col)) & 1 == 1 {
                        self.fill(
                            (ox + col * scale, y + row * scale),
                            (ox + (col + 1) * scale - 1, y + (row + 1) * scale - 1),
                            c,
                        );
                    }
                }
            }
        }
    }

    /// Width of `s` in pixels at `scale`.
    pub fn text_width(s: &str, scale: i64) -> i64 {
        // Text lengths are small.
        #[allow(clippy::cast_possible_wrap)]
        let n = s.chars().count() as i64;
        (4 * n - 1).max(0) * scale
    }

    /// Writes the canvas as a PNG file.
    ///
    /// # Errors
    /// I/O and encoding errors.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        write_png(path, self.width, self.height, &self.rgb)
    }
}

/// A "nice" tick spacing: 1, 2 or 5 × 10^k, giving about `n` ticks over `span`.
fn tick_step(span: f64, n: f64) -> f64 {
    let raw = (span / n).max(f64::MIN_POSITIVE);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nice = if f < 1.5 {
        1.0
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

fn label(v: f64, step: f64) -> String {
    if step >= 1.0 {
        format!("{v:.0}")
    } else if step >= 0.1 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// One series of a line plot.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Colour.
    pub color: Rgb,
    /// (x, y) points in drawing order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

/// A line plot with a title, axis labels, numbered ticks and a legend.
#[derive(Debug, Clone, Default)]
pub struct LinePlot {
    /// Title, above the plot.
    pub title: String,
    /// X-axis label.
    pub x_label: String,
    /// Y-axis label.
    pub y_label: String,
    /// The series.
    pub series: Vec<Series>,
    /// Fixed y range, or `None` to fit the data (from 0 when all values are positive).
    pub y_range: Option<(f64, f64)>,
}

impl LinePlot {
    /// Draws the plot on a `width` × `height` canvas.
    pub fn render(&self, width: usize, height: usize) -> Canvas {
        let mut c = Canvas::new(width, height);
        let pts = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
        };
        let (mut x0, mut x1) = pts().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
        let (mut y0, mut y1) = self.y_range.unwrap_or_else(|| {
            let (a, b) = pts().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.1), b.max(p.1))
            });
            (a.min(0.0), b)
        });
        if !(x0.is_finite() && x1.is_finite()) {
            (x0, x1) = (0.0, 1.0);
        }
        if !(y0.is_finite() && y1.is_finite()) {
            (y0, y1) = (0.0, 1.0);
        }
        if x1 - x0 <= 0.0 {
            x1 = x0 + 1.0;
        }
        if y1 - y0 <= 0.0 {
            y1 = y0 + 1.0;
        }
        let ys = tick_step(y1 - y0, 5.0);
        y1 = (y1 / ys).ceil() * ys;
        y0 = (y0 / ys).floor() * ys;
        let xs = tick_step(x1 - x0, 6.0);
        // Pixel sizes are small.
        #[allow(clippy::cast_possible_wrap)]
        let (w, h) = (width as i64, height as i64);
        let (left, right, top, bottom) = (70, w - 20, 70, h - 50);
        // Plot coordinates are clamped near the canvas: the casts cannot overflow.
        #[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
        let px = |x: f64| left + ((x - x0) / (x1 - x0) * (right - left) as f64).round() as i64;
        #[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
        let py = |y: f64| bottom - ((y - y0) / (y1 - y0) * (bottom - top) as f64).round() as i64;
        let grey = [225, 225, 225];
        let black = [0, 0, 0];
        let mut t = (y0 / ys).ceil() * ys;
        while t <= y1 + 1e-9 * ys {
            c.line((left, py(t)), (right, py(t)), grey, 1);
            let s = label(t, ys);
            c.text(
                left - 8 - Canvas::text_width(&s, 2),
                py(t) - 5,
                &s,
                black,
                2,
            );
            t += ys;
        }
        let mut t = (x0 / xs).ceil() * xs;
        while t <= x1 + 1e-9 * xs {
            c.line((px(t), top), (px(t), bottom), grey, 1);
            let s = label(t, xs);
            c.text(
                px(t) - Canvas::text_width(&s, 2) / 2,
                bottom + 8,
                &s,
                black,
                2,
            );
            t += xs;
        }
        c.line((left, top), (left, bottom), black, 1);
        c.line((left, bottom), (right, bottom), black, 1);
        c.line((left, top), (right, top), black, 1);
        c.line((right, top), (right, bottom), black, 1);
        for s in &self.series {
            let mut last: Option<(i64, i64)> = None;
            for &(x, y) in &s.points {
                if !(x.is_finite() && y.is_finite()) {
                    last = None;
                    continue;
                }
                let p = (px(x), py(y.clamp(y0, y1)));
                if let Some(q) = last {
                    c.line(q, p, s.color, 2);
                }
                last = Some(p);
            }
        }
        c.text(left, 12, &self.title, black, 3);
        c.text(
            (left + right) / 2 - Canvas::text_width(&self.x_label, 2) / 2,
            h - 20,
            &self.x_label,
            black,
            2,
        );
        c.text(8, top - 22, &self.y_label, black, 2);
        // Legend, top right inside the plot.
        let mut ly = top + 8;
        for s in &self.series {
            let lw = Canvas::text_width(&s.label, 2);
            c.fill((right - lw - 40, ly), (right - 8, ly + 14), [255, 255, 255]);
            c.line(
                (right - lw - 36, ly + 5),
                (right - lw - 16, ly + 5),
                s.color,
                3,
            );
            c.text(right - lw - 10, ly, &s.label, black, 2);
            ly += 18;
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice() {
        assert!((tick_step(10.0, 5.0) - 2.0).abs() < 1e-12);
        assert!((tick_step(1.0, 5.0) - 0.2).abs() < 1e-12);
        assert!((tick_step(700.0, 6.0) - 100.0).abs() < 1e-9);
    }

    #[test]
    fn a_plot_draws_its_series_in_their_colour() {
        let plot = LinePlot {
            title: "T".into(),
            x_label: "X".into(),
            y_label: "Y".into(),
            series: vec![Series {
                label: "A".into(),
                color: [200, 0, 0],
                points: vec![(0.0, 0.0), (10.0, 1.0), (f64::NAN, 3.0)],
            }],
            y_range: None,
        };
        let c = plot.render(300, 200);
        let red = (0..c.width())
            .flat_map(|x| (0..c.height()).map(move |y| (x, y)))
            .filter(|&(x, y)| c.get(x, y) == [200, 0, 0])
            .count();
        assert!(red > 200, "{red} red pixels");
        // An empty plot still renders.
        let empty = LinePlot::default().render(100, 80);
        assert_eq!(empty.get(99, 79), [255, 255, 255]);
    }

    #[test]
    fn text_sets_glyph_pixels() {
        let mut c = Canvas::new(20, 10);
        c.text(0, 0, "1", [0, 0, 0], 1);
        // "1" is 010 / 110 / 010 / 010 / 111.
        assert_eq!(c.get(1, 0), [0, 0, 0]);
        assert_eq!(c.get(0, 0), [255, 255, 255]);
        assert_eq!(c.get(0, 4), [0, 0, 0]);
    }
}
