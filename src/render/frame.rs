//! One frame: primary rays per pixel over 16x16 tiles in parallel, shading with shadow rays,
//! or the traversal-work heat map with its legend.

use super::font::{draw_label, text_height, text_width};
use super::shade::{Stage, heat_color, highlight, irradiance, smoothstep, to_srgb};
use super::trace::Tracer;
use crate::bvh::TraversalStats;
use crate::geom::Ray;
use glam::Vec3;
use image::RgbImage;
use rayon::prelude::*;

/// Side of a square tile of pixels, the unit of parallel work.
pub const TILE: u32 = 16;

/// What to draw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Interpolated vertex normals (else flat triangles).
    pub smooth: bool,
    /// Cast a shadow ray toward the key light from each lit point.
    pub shadows: bool,
    /// Colour pixels by traversal work (nodes visited plus triangles tested, primary and
    /// shadow rays) on a scale from 0 to this value, instead of shading them.
    pub heatmap: Option<u32>,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            smooth: true,
            shadows: true,
            heatmap: None,
        }
    }
}

/// What a frame cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameCounts {
    /// Primary rays (one per pixel).
    pub primary: u64,
    /// Shadow rays.
    pub shadow: u64,
    /// Primary rays that hit the scene's triangles.
    pub hits: u64,
    /// Traversal work, counted in heat-map mode only.
    pub work: TraversalStats,
    /// Pixels that cost any traversal work (heat-map mode).
    pub worked: u64,
    /// Most work of one pixel (heat-map mode).
    pub max_work: u64,
}

impl FrameCounts {
    fn add(mut self, o: Self) -> Self {
        self.primary += o.primary;
        self.shadow += o.shadow;
        self.hits += o.hits;
        self.work += o.work;
        self.worked += o.worked;
        self.max_work = self.max_work.max(o.max_work);
        self
    }

    /// Mean work (nodes plus triangles) over the pixels that cost any, in heat-map mode.
    #[must_use]
    pub fn work_per_pixel(&self) -> f64 {
        (self.work.nodes + self.work.prims) as f64 / self.worked.max(1) as f64
    }
}

/// Renders frames into reused buffers.
pub struct Renderer {
    settings: Settings,
    tiles: Vec<[u8; 3]>,
}

impl Renderer {
    /// A renderer for `settings`.
    #[must_use]
    pub fn new(settings: Settings) -> Self {
        Self {
            settings,
            tiles: Vec::new(),
        }
    }

    /// The settings.
    #[must_use]
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Renders the scene `tracer` answers for, seen from `stage`, into `out` (resized to the
    /// settings' size when it differs). Allocates nothing once the buffers have their size.
    pub fn render<T: Tracer>(
        &mut self,
        tracer: &T,
        stage: &Stage,
        out: &mut RgbImage,
    ) -> FrameCounts {
        let s = self.settings;
        let (w, h) = (s.width.max(1), s.height.max(1));
        if out.dimensions() != (w, h) {
            *out = RgbImage::new(w, h);
        }
        let ntx = w.div_ceil(TILE);
        let nty = h.div_ceil(TILE);
        let per_tile = (TILE * TILE) as usize;
        self.tiles.resize((ntx * nty) as usize * per_tile, [0; 3]);
        let rays = stage.camera.rays(w, h);
        let counts = self
            .tiles
            .par_chunks_mut(per_tile)
            .enumerate()
            .map(|(i, tile)| {
                let (x0, y0) = ((i as u32 % ntx) * TILE, (i as u32 / ntx) * TILE);
                let mut c = FrameCounts::default();
                for py in 0..TILE.min(h - y0) {
                    for px in 0..TILE.min(w - x0) {
                        let ray = rays.ray(x0 + px, y0 + py);
                        tile[(py * TILE + px) as usize] = pixel(tracer, stage, &s, &ray, &mut c);
                    }
                }
                c
            })
            .reduce(FrameCounts::default, FrameCounts::add);
        // Tiles back into rows.
        let raw: &mut [u8] = out;
        for (i, tile) in self.tiles.chunks(per_tile).enumerate() {
            let (x0, y0) = ((i as u32 % ntx) * TILE, (i as u32 / ntx) * TILE);
            let tw = TILE.min(w - x0) as usize;
            for py in 0..TILE.min(h - y0) {
                let row = &tile[(py * TILE) as usize..][..tw];
                let at = ((y0 + py) as usize * w as usize + x0 as usize) * 3;
                for (d, p) in raw[at..at + tw * 3].chunks_exact_mut(3).zip(row) {
                    d.copy_from_slice(p);
                }
            }
        }
        if let Some(max) = s.heatmap {
            draw_heat_legend(out, max);
        }
        counts
    }
}

/// Traces and shades one pixel.
#[inline]
fn pixel<T: Tracer>(
    tracer: &T,
    stage: &Stage,
    s: &Settings,
    ray: &Ray,
    c: &mut FrameCounts,
) -> [u8; 3] {
    c.primary += 1;
    let mut work = TraversalStats::default();
    let counting = s.heatmap.is_some();
    let hit = tracer.closest(ray, s.smooth, counting.then_some(&mut work));
    let d = ray.dir;
    // The ground, when it is nearer than any triangle.
    let ground = stage.ground.and_then(|g| {
        if d.y >= 0.0 || ray.origin.y <= g.height {
            return None;
        }
        let t = (g.height - ray.origin.y) / d.y;
        if hit.is_some_and(|h| h.t <= t) {
            return None;
        }
        let p = ray.at(t);
        let r = Vec3::new(p.x - g.center.x, 0.0, p.z - g.center.z).length();
        let fade = smoothstep(g.inner, g.outer, r);
        (fade < 1.0).then_some((p, fade, g.tile))
    });
    let mut shadow = |from: Vec3, work: &mut TraversalStats| -> f32 {
        c.shadow += 1;
        let r = Ray::new(from, stage.light);
        if tracer.occluded(&r, counting.then_some(work)) {
            0.0
        } else {
            1.0
        }
    };
    let color = if let Some((p, fade, tile)) = ground {
        let lit = if s.shadows {
            shadow(p + Vec3::Y * stage.offset, &mut work)
        } else {
            1.0
        };
        let check = ((p.x / tile).floor() + (p.z / tile).floor()).rem_euclid(2.0);
        let albedo = if check < 0.5 { 0.50 } else { 0.40 };
        let lit_color = irradiance(Vec3::Y, stage.light, lit) * albedo;
        lit_color.lerp(stage.background(d), fade)
    } else if let Some(h) = hit {
        c.hits += 1;
        let mut ng = h.geometric.normalize_or_zero();
        if ng.dot(d) > 0.0 {
            ng = -ng;
        }
        let mut n = h.shading.normalize_or_zero();
        if n.dot(ng) < 0.0 {
            n = -n;
        }
        let facing = ng.dot(stage.light) > 0.0 && n.dot(stage.light) > 0.0;
        let lit = if !facing {
            0.0
        } else if s.shadows {
            shadow(ray.at(h.t) + ng * stage.offset, &mut work)
        } else {
            1.0
        };
        stage.albedo(h.instance) * irradiance(n, stage.light, lit)
            + Vec3::splat(highlight(n, d, stage.light, lit))
    } else {
        stage.background(d)
    };
    match s.heatmap {
        Some(max) => {
            c.work += work;
            let w = work.nodes + work.prims;
            c.worked += u64::from(w > 0);
            c.max_work = c.max_work.max(w);
            heat_color(w as f32, max as f32)
        }
        None => to_srgb(color),
    }
}

/// Draws the heat map's legend along the bottom of `img`: the colour bar from 0 to `max` with
/// ticks and numbers, and what it measures.
pub fn draw_heat_legend(img: &mut RgbImage, max: u32) {
    let (w, h) = img.dimensions();
    let scale = (h / 240).max(1);
    let bar_h = 4 * scale + 2;
    let margin = 4 * scale;
    let text_h = text_height(scale);
    let panel_h = margin * 3 + bar_h + 2 * scale + text_h * 2 + scale * 2;
    if h < panel_h + 8 || w < 64 {
        return;
    }
    let top = h - panel_h;
    // Darken the panel so the legend reads on any picture.
    for y in top..h {
        for x in 0..w {
            let p = img.get_pixel_mut(x, y);
            p.0 = p.0.map(|v| v / 4);
        }
    }
    let title = "WORK PER PIXEL: NODES + TRIANGLES";
    let x0 = margin * 2;
    let x1 = w - margin * 2;
    draw_label(
        img,
        i64::from(x0),
        i64::from(top + margin),
        scale,
        title,
        [230; 3],
    );
    let bar_top = top + margin * 2 + text_h;
    let span = (x1 - x0).max(1);
    for x in x0..x1 {
        let v = (x - x0) as f32 / span as f32 * max as f32;
        let c = heat_color(v, max as f32);
        for y in bar_top..bar_top + bar_h {
            img.put_pixel(x, y, image::Rgb(c));
        }
    }
    let ticks = tick_values(max);
    for &v in &ticks {
        let x = x0 + ((v as f64 / f64::from(max.max(1))) * f64::from(span)).round() as u32;
        let x = x.min(x1 - 1);
        for y in bar_top + bar_h..bar_top + bar_h + 2 * scale {
            for dx in 0..scale {
                if x + dx < w {
                    img.put_pixel(x + dx, y, image::Rgb([230; 3]));
                }
            }
        }
        let label = if v == max {
            format!("{v}+")
        } else {
            v.to_string()
        };
        let tw = text_width(&label, scale);
        let lx = i64::from(x) - i64::from(tw / 2);
        let lx = lx.clamp(0, i64::from(w.saturating_sub(tw)));
        draw_label(
            img,
            lx,
            i64::from(bar_top + bar_h + 3 * scale),
            scale,
            &label,
            [230; 3],
        );
    }
}

/// Round tick values from 0 to `max` (about five steps, `max` itself included).
fn tick_values(max: u32) -> Vec<u32> {
    if max == 0 {
        return vec![0];
    }
    let raw = f64::from(max) / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * p)
        .max(1.0)
        .round() as u32;
    let mut v: Vec<u32> = (0..).map(|k| k * step).take_while(|&x| x < max).collect();
    if let Some(&last) = v.last()
        && 2 * (max - last) <= step
        && last != 0
    {
        v.pop();
    }
    v.push(max);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_end_at_max() {
        assert_eq!(tick_values(200), vec![0, 50, 100, 150, 200]);
        assert_eq!(tick_values(100), vec![0, 20, 40, 60, 80, 100]);
        assert_eq!(tick_values(300), vec![0, 100, 200, 300]);
        assert_eq!(tick_values(7), vec![0, 2, 4, 7]);
    }
}
