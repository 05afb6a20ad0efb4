//! Pictures a person reads without the viewer: occupancy maps at a fixed scale with axes in
//! metres, a scale bar and a legend, the trajectories and landmarks drawn on them; the Hough
//! accumulator with its axes; a tag plan. Drawn with embedded-graphics (shapes and its built-in
//! fonts) onto an RGB image.

use crate::sonar::grid::OccupancyMap;
use crate::sonar::hough::Accumulator;
use embedded_graphics::mono_font::ascii::{FONT_6X10, FONT_7X13_BOLD};
use embedded_graphics::mono_font::{MonoTextStyle, MonoTextStyleBuilder};
use embedded_graphics::pixelcolor::Rgb888;
use embedded_graphics::prelude::*;
use embedded_graphics::primitives::{
    Circle, Line, Polyline, PrimitiveStyle, PrimitiveStyleBuilder, Rectangle,
};
use embedded_graphics::text::{Alignment, Baseline, Text, TextStyleBuilder};
use image::RgbImage;

/// Pixels per metre of a map picture (a 16 m home is 640 pixels across).
pub const MAP_PX_PER_M: f64 = 40.0;
/// Pixels per metre of a map larger than [`LARGE_MAP_M`] (a building), so that it stays under
/// about 2,500 pixels.
pub const LARGE_MAP_PX_PER_M: f64 = 20.0;
/// A map wider or taller than this many metres is drawn at [`LARGE_MAP_PX_PER_M`].
pub const LARGE_MAP_M: f64 = 60.0;
/// Margin kept around the observed part of a map, metres.
const MAP_MARGIN_M: f64 = 0.5;

/// Colour of an unknown cell: blue-grey, unlike any shade of free (white) to occupied (black).
pub const UNKNOWN: [u8; 3] = [196, 206, 222];

/// Colours of what is drawn on a map.
pub mod colours {
    /// The odometry's trajectory.
    pub const ODOMETRY: [u8; 3] = [214, 39, 40];
    /// The online filter's trajectory.
    pub const ONLINE: [u8; 3] = [255, 127, 14];
    /// The offline pose graph's trajectory.
    pub const OFFLINE: [u8; 3] = [31, 119, 180];
    /// The ground truth.
    pub const GROUND_TRUTH: [u8; 3] = [44, 160, 44];
    /// Landmarks (surveyed tags).
    pub const LANDMARK: [u8; 3] = [148, 103, 189];
    /// Hough corners.
    pub const CORNER: [u8; 3] = [23, 190, 207];
}

/// A line drawn on a map: a trajectory.
#[derive(Debug, Clone)]
pub struct Path<'a> {
    /// Legend text.
    pub label: &'a str,
    /// RGB colour.
    pub colour: [u8; 3],
    /// Points in metres.
    pub points: Vec<[f64; 2]>,
}

/// A point drawn on a map: a landmark, a corner, a proposed tag.
#[derive(Debug, Clone)]
pub struct Mark {
    /// Where, metres.
    pub at_m: [f64; 2],
    /// RGB colour.
    pub colour: [u8; 3],
    /// Text beside it (empty: none).
    pub label: String,
}

/// What to draw on a map besides its cells.
#[derive(Debug, Clone, Default)]
pub struct Overlay<'a> {
    /// Trajectories, drawn in order.
    pub paths: Vec<Path<'a>>,
    /// Points, drawn over the trajectories.
    pub marks: Vec<Mark>,
    /// Legend entries of the marks: (text, colour).
    pub mark_legend: Vec<(&'a str, [u8; 3])>,
    /// A colour for each map cell (row-major) drawn instead of its occupancy, `None` to keep
    /// it; empty: none.
    pub cells: Vec<Option<[u8; 3]>>,
    /// Legend entries of the cell colours.
    pub cell_legend: Vec<(&'a str, [u8; 3])>,
}

/// An RGB image as an embedded-graphics drawing surface.
struct Canvas(RgbImage);

impl OriginDimensions for Canvas {
    fn size(&self) -> Size {
        Size::new(self.0.width(), self.0.height())
    }
}

impl DrawTarget for Canvas {
    type Color = Rgb888;
    type Error = std::convert::Infallible;

    fn draw_iter<I: IntoIterator<Item = Pixel<Rgb888>>>(
        &mut self,
        pixels: I,
    ) -> Result<(), Self::Error> {
        let (w, h) = self.0.dimensions();
        for Pixel(p, c) in pixels {
            if let (Ok(x), Ok(y)) = (u32::try_from(p.x), u32::try_from(p.y)) {
                if x < w && y < h {
                    self.0.put_pixel(x, y, image::Rgb([c.r(), c.g(), c.b()]));
                }
            }
        }
        Ok(())
    }
}

fn rgb(c: [u8; 3]) -> Rgb888 {
    Rgb888::new(c[0], c[1], c[2])
}

const INK: Rgb888 = Rgb888::new(40, 40, 40);
const PAPER: Rgb888 = Rgb888::new(255, 255, 255);

/// Space around the plot area, pixels: left (tick labels), right, bottom (tick labels and the x
/// axis's name); the top holds the title, the legend's rows and the y axis's name.
const LEFT: i32 = 56;
const RIGHT: i32 = 24;
const BOTTOM: i32 = 46;
/// Height of the title row and of each legend row, pixels.
const TITLE_ROW: i32 = 22;
const LEGEND_ROW: i32 = 16;
/// Width of a character of the fonts, pixels (FONT_6X10; the title's FONT_7X13_BOLD is 7).
const CHAR_W: i32 = 6;
/// Smallest picture width, so that a title and a legend fit, pixels.
const MIN_WIDTH: i32 = 640;
/// Smallest distance between two ticks of an axis, pixels.
const TICK_SPACING_PX: f64 = 40.0;

/// A legend entry: text and colour.
type Entry<'a> = (&'a str, Rgb888);

/// A plot: data coordinates `lo..hi` on both axes drawn at `scale` pixels per unit.
struct Plot {
    canvas: Canvas,
    lo: [f64; 2],
    hi: [f64; 2],
    scale: [f64; 2],
    top: i32,
}

/// Width of a legend entry, pixels.
fn entry_width(text: &str) -> i32 {
    16 + CHAR_W * text.len() as i32 + 14
}

/// The legend's entries in rows of at most `width` pixels.
fn legend_rows<'a, 'b>(entries: &'b [Entry<'a>], width: i32) -> Vec<&'b [Entry<'a>]> {
    let mut rows = Vec::new();
    let (mut start, mut used) = (0, 0);
    for (i, (text, _)) in entries.iter().enumerate() {
        let w = entry_width(text);
        if used > 0 && used + w > width {
            rows.push(&entries[start..i]);
            (start, used) = (i, 0);
        }
        used += w;
    }
    if start < entries.len() {
        rows.push(&entries[start..]);
    }
    rows
}

impl Plot {
    /// A plot of `lo..hi` at `scale` with `title`, `legend` and the y axis's name above it,
    /// its x range widened about its middle to fit the title and [`MIN_WIDTH`].
    fn new(
        mut lo: [f64; 2],
        mut hi: [f64; 2],
        scale: [f64; 2],
        title: &str,
        legend: &[Entry<'_>],
        y_name: &str,
    ) -> Self {
        let needed = (7 * title.len() as i32).max(MIN_WIDTH - LEFT - RIGHT) as f64;
        let w = (hi[0] - lo[0]) * scale[0];
        if w < needed {
            let grow = 0.5 * (needed - w) / scale[0];
            lo[0] -= grow;
            hi[0] += grow;
        }
        let w = ((hi[0] - lo[0]) * scale[0]).ceil() as i32;
        let h = ((hi[1] - lo[1]) * scale[1]).ceil() as i32;
        let rows = legend_rows(legend, w);
        let top = TITLE_ROW + LEGEND_ROW * rows.len() as i32 + LEGEND_ROW + 6;
        let img = RgbImage::from_pixel(
            (w + LEFT + RIGHT) as u32,
            (h + top + BOTTOM) as u32,
            image::Rgb([255, 255, 255]),
        );
        let mut plot = Self {
            canvas: Canvas(img),
            lo,
            hi,
            scale,
            top,
        };
        plot.text(title, Point::new(LEFT, 11), FONT_7X13_BOLD, Alignment::Left);
        for (k, row) in rows.iter().enumerate() {
            plot.legend_row(row, TITLE_ROW + 6 + LEGEND_ROW * k as i32);
        }
        plot.text(y_name, Point::new(8, top - 10), FONT_6X10, Alignment::Left);
        plot
    }

    /// Pixel of a data point (y up).
    fn px(&self, p: [f64; 2]) -> Point {
        Point::new(
            LEFT + ((p[0] - self.lo[0]) * self.scale[0]).round() as i32,
            self.top + ((self.hi[1] - p[1]) * self.scale[1]).round() as i32,
        )
    }

    fn area(&self) -> Rectangle {
        Rectangle::with_corners(self.px(self.lo), self.px(self.hi))
    }

    fn text(
        &mut self,
        s: &str,
        at: Point,
        font: embedded_graphics::mono_font::MonoFont<'static>,
        align: Alignment,
    ) {
        let style = MonoTextStyle::new(&font, INK);
        let layout = TextStyleBuilder::new()
            .alignment(align)
            .baseline(Baseline::Middle)
            .build();
        let _ = Text::with_text_style(s, at, style, layout).draw(&mut self.canvas);
    }

    /// A label on a white box, so it reads over anything.
    fn label(&mut self, s: &str, at: Point) {
        let style = MonoTextStyleBuilder::new()
            .font(&FONT_6X10)
            .text_color(INK)
            .background_color(PAPER)
            .build();
        let _ = Text::with_baseline(s, at, style, Baseline::Middle).draw(&mut self.canvas);
    }

    /// Fills the data rectangle `[x0, x1] x [y0, y1]`.
    fn fill(&mut self, x: [f64; 2], y: [f64; 2], colour: Rgb888) {
        let r = Rectangle::with_corners(self.px([x[0], y[1]]), self.px([x[1], y[0]]));
        let _ = r
            .into_styled(PrimitiveStyle::with_fill(colour))
            .draw(&mut self.canvas);
    }

    /// The frame, ticks and tick labels of both axes, and the x axis's name.
    fn axes(&mut self, x_name: &str) {
        let frame = PrimitiveStyleBuilder::new()
            .stroke_color(INK)
            .stroke_width(1)
            .build();
        let _ = self.area().into_styled(frame).draw(&mut self.canvas);
        let tick = PrimitiveStyle::with_stroke(INK, 1);
        for axis in 0..2 {
            let step = nice_step(TICK_SPACING_PX / self.scale[axis]);
            let mut v = (self.lo[axis] / step).ceil() * step;
            while v <= self.hi[axis] + 1e-9 {
                let text = format_tick(v, step);
                if axis == 0 {
                    let p = self.px([v, self.lo[1]]);
                    let _ = Line::new(p, p + Point::new(0, 5))
                        .into_styled(tick)
                        .draw(&mut self.canvas);
                    self.text(&text, p + Point::new(0, 12), FONT_6X10, Alignment::Center);
                } else {
                    let p = self.px([self.lo[0], v]);
                    let _ = Line::new(p - Point::new(5, 0), p)
                        .into_styled(tick)
                        .draw(&mut self.canvas);
                    self.text(&text, p - Point::new(8, 0), FONT_6X10, Alignment::Right);
                }
                v += step;
            }
        }
        let bottom = self.px([0.5 * (self.lo[0] + self.hi[0]), self.lo[1]]);
        self.text(
            x_name,
            bottom + Point::new(0, 30),
            FONT_6X10,
            Alignment::Center,
        );
    }

    /// A scale bar of `length` data units labelled `text`, in the plot's lower right corner.
    fn scale_bar(&mut self, length: f64, text: &str) {
        let end = self.px([self.hi[0], self.lo[1]]) + Point::new(-12, -14);
        let start = end - Point::new((length * self.scale[0]).round() as i32, 0);
        let _ = Rectangle::with_corners(start - Point::new(4, 14), end + Point::new(4, 6))
            .into_styled(PrimitiveStyle::with_fill(PAPER))
            .draw(&mut self.canvas);
        let bar = PrimitiveStyle::with_stroke(INK, 3);
        let _ = Line::new(start, end)
            .into_styled(bar)
            .draw(&mut self.canvas);
        self.text(
            text,
            Point::new((start.x + end.x) / 2, start.y - 8),
            FONT_6X10,
            Alignment::Center,
        );
    }

    /// A row of the legend at height `y`: a swatch and text per entry.
    fn legend_row(&mut self, entries: &[Entry<'_>], y: i32) {
        let mut x = LEFT;
        for (text, colour) in entries {
            let _ = Rectangle::new(Point::new(x, y - 5), Size::new(12, 10))
                .into_styled(
                    PrimitiveStyleBuilder::new()
                        .fill_color(*colour)
                        .stroke_color(INK)
                        .stroke_width(1)
                        .build(),
                )
                .draw(&mut self.canvas);
            self.text(text, Point::new(x + 16, y), FONT_6X10, Alignment::Left);
            x += entry_width(text);
        }
    }

    fn finish(self) -> RgbImage {
        self.canvas.0
    }
}

/// A round step near `raw`: 1, 2 or 5 times a power of ten.
fn nice_step(raw: f64) -> f64 {
    let raw = raw.max(1e-9);
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * power)
}

fn format_tick(v: f64, step: f64) -> String {
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    if step >= 1.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

/// The part of `map` worth drawing: its observed cells and `extra` points with a margin,
/// within the grid. The whole grid when nothing is observed.
fn map_window(map: &OccupancyMap, extra: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let g = &map.geometry;
    let grid_lo = g.origin_m;
    let grid_hi = [
        g.origin_m[0] + g.width as f64 * g.resolution_m,
        g.origin_m[1] + g.height as f64 * g.resolution_m,
    ];
    let Some((mut lo, mut hi)) = map.known_extent() else {
        return (grid_lo, grid_hi);
    };
    for p in extra {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (
        [
            (lo[0] - MAP_MARGIN_M).max(grid_lo[0]),
            (lo[1] - MAP_MARGIN_M).max(grid_lo[1]),
        ],
        [
            (hi[0] + MAP_MARGIN_M).min(grid_hi[0]),
            (hi[1] + MAP_MARGIN_M).min(grid_hi[1]),
        ],
    )
}

/// Points of a path drawn as one polyline (consecutive pieces share their end point).
const POLYLINE_PIECE: usize = 16;

/// The points of a path as the picture draws them: a point less than 2 pixels from the last one
/// kept is left out (the last point is always kept). A run's path has a pose every centimetre or
/// so, several to a pixel, and the thick line's joins cost as much as its segments.
fn distinct_pixels(points: impl Iterator<Item = Point>) -> Vec<Point> {
    let mut out: Vec<Point> = Vec::new();
    let mut last_dropped = None;
    for p in points {
        match out.last() {
            Some(q) if (p - *q).x.abs().max((p - *q).y.abs()) < 2 => last_dropped = Some(p),
            _ => {
                out.push(p);
                last_dropped = None;
            }
        }
    }
    out.extend(last_dropped);
    out
}

/// A picture of an occupancy map: each cell from white (free) to black (occupied), unknown cells
/// blue-grey, at [`MAP_PX_PER_M`] with axes in metres, a 1 m scale bar, a legend, and `overlay`
/// drawn over it.
pub fn map_picture(map: &OccupancyMap, title: &str, overlay: &Overlay<'_>) -> RgbImage {
    let extra: Vec<[f64; 2]> = overlay
        .paths
        .iter()
        .flat_map(|p| p.points.iter().copied())
        .chain(overlay.marks.iter().map(|m| m.at_m))
        .collect();
    let (lo, hi) = map_window(map, &extra);
    let scale = if (hi[0] - lo[0]).max(hi[1] - lo[1]) > LARGE_MAP_M {
        LARGE_MAP_PX_PER_M
    } else {
        MAP_PX_PER_M
    };
    let unknown = rgb(UNKNOWN);
    let mut legend = vec![("free", PAPER), ("occupied", INK), ("unknown", unknown)];
    legend.extend(overlay.paths.iter().map(|p| (p.label, rgb(p.colour))));
    legend.extend(overlay.cell_legend.iter().map(|(t, c)| (*t, rgb(*c))));
    legend.extend(overlay.mark_legend.iter().map(|(t, c)| (*t, rgb(*c))));
    let mut plot = Plot::new(lo, hi, [scale, scale], title, &legend, "y (m)");
    let (lo, hi) = (plot.lo, plot.hi);
    let g = &map.geometry;
    plot.fill([lo[0], hi[0]], [lo[1], hi[1]], unknown);
    for (i, cell) in map.occupancy.iter().enumerate() {
        let Some(occupancy) = cell else { continue };
        let [x, y] = g.centre(i % g.width, i / g.width);
        let half = 0.5 * g.resolution_m;
        if x + half < lo[0] || x - half > hi[0] || y + half < lo[1] || y - half > hi[1] {
            continue;
        }
        let v = (255.0 * (1.0 - occupancy.clamp(0.0, 1.0))).round() as u8;
        let colour = match overlay.cells.get(i).copied().flatten() {
            Some(c) => rgb(c),
            None => Rgb888::new(v, v, v),
        };
        plot.fill([x - half, x + half], [y - half, y + half], colour);
    }
    for path in &overlay.paths {
        let points = distinct_pixels(path.points.iter().map(|&p| plot.px(p)));
        // In short pieces: a thick polyline is filled scanline by scanline over its bounding box,
        // each scanline against every segment, so a whole run's path in one costs its rows times
        // its segments.
        let mut start = 0;
        while start + 1 < points.len() {
            let end = (start + POLYLINE_PIECE).min(points.len());
            let _ = Polyline::new(&points[start..end])
                .into_styled(PrimitiveStyle::with_stroke(rgb(path.colour), 2))
                .draw(&mut plot.canvas);
            start = end - 1;
        }
    }
    for mark in &overlay.marks {
        let centre = plot.px(mark.at_m);
        let _ = Circle::with_center(centre, 11)
            .into_styled(
                PrimitiveStyleBuilder::new()
                    .fill_color(rgb(mark.colour))
                    .stroke_color(INK)
                    .stroke_width(1)
                    .build(),
            )
            .draw(&mut plot.canvas);
        if !mark.label.is_empty() {
            plot.label(&mark.label, centre + Point::new(8, -8));
        }
    }
    plot.axes("x (m)");
    plot.scale_bar(1.0, "1 m");
    plot.finish()
}

/// Pixels per bin of the Hough accumulator picture.
const HOUGH_PX_PER_BIN: f64 = 2.0;

/// A picture of the Hough accumulator: each bin's votes (log scale, darker is more) by the
/// bearing of the voted point from the map origin (degrees, across) and its distance (metres,
/// up), with axes.
pub fn accumulator_picture(acc: &Accumulator, title: &str) -> RgbImage {
    let (rho_step, phi_step) = (acc.rho_step_m(), acc.phi_step_deg());
    let max = acc.votes.iter().copied().max().unwrap_or(0).max(1) as f64;
    // Up to the farthest bin with votes, and a metre more.
    let used = acc
        .votes
        .iter()
        .rposition(|&v| v > 0)
        .map_or(acc.n_rho, |i| i / acc.n_phi + 1);
    let rho_hi = ((used as f64 * rho_step + 1.0).ceil()).min(acc.n_rho as f64 * rho_step);
    let votes_text = format!("{max:.0} votes (log scale)");
    let mut plot = Plot::new(
        [0.0, 0.0],
        [acc.n_phi as f64 * phi_step, rho_hi],
        [HOUGH_PX_PER_BIN / phi_step, HOUGH_PX_PER_BIN / rho_step],
        title,
        &[("no votes", PAPER), (&votes_text, INK)],
        "distance of the echo from the map origin (m)",
    );
    for (i, &v) in acc.votes.iter().enumerate() {
        if v == 0 || (i / acc.n_phi) >= used {
            continue;
        }
        let (ir, ip) = ((i / acc.n_phi) as f64, (i % acc.n_phi) as f64);
        let shade = 255.0 * (1.0 - (1.0 + v as f64).ln() / (1.0 + max).ln());
        let s = shade.round() as u8;
        plot.fill(
            [ip * phi_step, (ip + 1.0) * phi_step],
            [ir * rho_step, (ir + 1.0) * rho_step],
            Rgb888::new(s, s, s),
        );
    }
    plot.axes("bearing of the echo from the map origin (deg)");
    plot.finish()
}

impl<'a> Path<'a> {
    /// A trajectory's positions.
    pub fn trajectory(
        label: &'a str,
        colour: [u8; 3],
        poses: &[crate::geometry::StampedPose],
    ) -> Self {
        Self {
            label,
            colour,
            points: poses.iter().map(|p| [p.pose.x, p.pose.y]).collect(),
        }
    }
}

impl Mark {
    /// Hough corners, unlabelled.
    pub fn corners(features: &[crate::sonar::hough::Feature]) -> Vec<Mark> {
        features
            .iter()
            .map(|f| Mark {
                at_m: [f.x_m, f.y_m],
                colour: colours::CORNER,
                label: String::new(),
            })
            .collect()
    }

    /// Landmarks labelled with their tag ids.
    pub fn landmarks(landmarks: &[crate::fusion::Landmark]) -> Vec<Mark> {
        landmarks
            .iter()
            .map(|l| Mark {
                at_m: [l.position_m[0], l.position_m[1]],
                colour: colours::LANDMARK,
                label: format!("tag {}", l.id),
            })
            .collect()
    }
}
