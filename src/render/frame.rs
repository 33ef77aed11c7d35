//! One frame: primary rays per pixel over 16x16 tiles in parallel, shading with shadow rays,
//! or the traversal-work heat map with its legend.

use super::font::{draw_label, text_height, text_width};
use super::shade::{Stage, heat_color, highlight, irradiance, smoothstep, to_srgb};
use super::trace::{Surface, Tracer};
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
    /// Heat-map mode: each tile pixel's work, in the tiles' layout.
    tile_work: Vec<u32>,
    /// Heat-map mode: each pixel's work (nodes plus triangles), row by row.
    work: Vec<u32>,
}

impl Renderer {
    /// A renderer for `settings`.
    #[must_use]
    pub fn new(settings: Settings) -> Self {
        Self {
            settings,
            tiles: Vec::new(),
            tile_work: Vec::new(),
            work: Vec::new(),
        }
    }

    /// Sets the top of the heat map's scale for the frames rendered from now on.
    pub fn set_heat_max(&mut self, max: u32) {
        if self.settings.heatmap.is_some() {
            self.settings.heatmap = Some(max.max(1));
        }
    }

    /// Heat-map mode: the work (nodes plus triangles) of the last frame's pixels, row by row.
    #[must_use]
    pub fn work(&self) -> &[u32] {
        &self.work
    }

    /// Heat-map mode: colours `out` from the last frame's work on a scale from 0 to `max` and
    /// draws the legend (what [`Renderer::render`] does with the settings' scale).
    pub fn recolor(&self, out: &mut RgbImage, max: u32) {
        for (p, &w) in out.pixels_mut().zip(&self.work) {
            p.0 = heat_pixel(w, max);
        }
        draw_heat_legend(out, max);
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
        self.tile_work.resize(self.tiles.len(), 0);
        let rays = stage.camera.rays(w, h);
        let counts = self
            .tiles
            .par_chunks_mut(per_tile)
            .zip(self.tile_work.par_chunks_mut(per_tile))
            .enumerate()
            .map(|(i, (tile, tile_work))| {
                let (x0, y0) = ((i as u32 % ntx) * TILE, (i as u32 / ntx) * TILE);
                let mut c = FrameCounts::default();
                let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
                if s.heatmap.is_none() {
                    tile_batched(
                        tracer,
                        stage,
                        &s,
                        tile,
                        (tw, th),
                        |px, py| rays.ray(x0 + px, y0 + py),
                        &mut c,
                    );
                    return c;
                }
                for py in 0..th {
                    for px in 0..tw {
                        let ray = rays.ray(x0 + px, y0 + py);
                        let k = (py * TILE + px) as usize;
                        tile_work[k] = heat_work(tracer, stage, &s, &ray, &mut c);
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
            self.work.resize((w * h) as usize, 0);
            for (i, tile) in self.tile_work.chunks(per_tile).enumerate() {
                let (x0, y0) = ((i as u32 % ntx) * TILE, (i as u32 / ntx) * TILE);
                let tw = TILE.min(w - x0) as usize;
                for py in 0..TILE.min(h - y0) {
                    let at = (y0 + py) as usize * w as usize + x0 as usize;
                    self.work[at..at + tw].copy_from_slice(&tile[(py * TILE) as usize..][..tw]);
                }
            }
            self.recolor(out, max);
        } else {
            self.work.clear();
        }
        counts
    }
}

/// What a primary ray sees, before its shadow ray is answered.
#[derive(Clone, Copy)]
enum Seen {
    /// The ground plane at `p`, faded out by `fade`, checkered with squares of side `tile`.
    Ground { p: Vec3, fade: f32, tile: f32 },
    /// A triangle: the hit, its geometric and shading normals turned toward the ray, and
    /// whether both face the light.
    Surface {
        h: Surface,
        ng: Vec3,
        n: Vec3,
        facing: bool,
    },
    /// Nothing: the sky.
    Sky,
}

/// Classifies what `ray` sees given its closest triangle hit.
#[inline]
fn see(stage: &Stage, ray: &Ray, hit: Option<Surface>) -> Seen {
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
    if let Some((p, fade, tile)) = ground {
        Seen::Ground { p, fade, tile }
    } else if let Some(h) = hit {
        let mut ng = super::trace::unit_or_zero(h.geometric);
        if ng.dot(d) > 0.0 {
            ng = -ng;
        }
        let mut n = super::trace::unit_or_zero(h.shading);
        if n.dot(ng) < 0.0 {
            n = -n;
        }
        let facing = ng.dot(stage.light) > 0.0 && n.dot(stage.light) > 0.0;
        Seen::Surface { h, ng, n, facing }
    } else {
        Seen::Sky
    }
}

/// The origin of the shadow ray `seen` needs, if any; and the light it gets without one.
#[inline]
fn shadow_origin(stage: &Stage, s: &Settings, ray: &Ray, seen: &Seen) -> (Option<Vec3>, f32) {
    match *seen {
        Seen::Ground { p, .. } => {
            if s.shadows {
                (Some(p + Vec3::Y * stage.offset), 1.0)
            } else {
                (None, 1.0)
            }
        }
        Seen::Surface { h, ng, facing, .. } => {
            if !facing {
                (None, 0.0)
            } else if s.shadows {
                (Some(ray.at(h.t) + ng * stage.offset), 1.0)
            } else {
                (None, 1.0)
            }
        }
        Seen::Sky => (None, 1.0),
    }
}

/// The linear colour of what `ray` sees, lit by `lit` (0 in shadow, 1 in the light).
#[inline]
fn color(stage: &Stage, ray: &Ray, seen: &Seen, lit: f32) -> Vec3 {
    let d = ray.dir;
    match *seen {
        Seen::Ground { p, fade, tile } => {
            let check = ((p.x / tile).floor() + (p.z / tile).floor()).rem_euclid(2.0);
            let albedo = if check < 0.5 { 0.50 } else { 0.40 };
            let lit_color = irradiance(Vec3::Y, stage.light, lit) * albedo;
            lit_color.lerp(stage.background(d), fade)
        }
        Seen::Surface { h, n, .. } => {
            stage.albedo(h.instance) * irradiance(n, stage.light, lit)
                + Vec3::splat(highlight(n, d, stage.light, lit))
        }
        Seen::Sky => stage.background(d),
    }
}

/// A heat-map pixel: the work (nodes plus triangles) its primary ray and its shadow ray cost.
#[inline]
fn heat_work<T: Tracer>(
    tracer: &T,
    stage: &Stage,
    s: &Settings,
    ray: &Ray,
    c: &mut FrameCounts,
) -> u32 {
    c.primary += 1;
    let mut work = TraversalStats::default();
    let hit = tracer.closest(ray, s.smooth, Some(&mut work));
    let seen = see(stage, ray, hit);
    if matches!(seen, Seen::Surface { .. }) {
        c.hits += 1;
    }
    if let (Some(from), _) = shadow_origin(stage, s, ray, &seen) {
        c.shadow += 1;
        tracer.occluded(&Ray::new(from, stage.light), Some(&mut work));
    }
    c.work += work;
    let w = work.nodes + work.prims;
    c.worked += u64::from(w > 0);
    c.max_work = c.max_work.max(w);
    u32::try_from(w).unwrap_or(u32::MAX)
}

/// The colour of pixels that cost no work (their rays left the scene's box untouched):
/// a neutral grey, apart from every colour of the scale.
pub const HEAT_BACKGROUND: [u8; 3] = [118, 118, 118];

/// A heat-map pixel's colour: [`HEAT_BACKGROUND`] without work, else its place on the scale.
#[must_use]
pub fn heat_pixel(work: u32, max: u32) -> [u8; 3] {
    if work == 0 {
        HEAT_BACKGROUND
    } else {
        heat_color(work as f32, max as f32)
    }
}

/// The `q`-quantile (0..=1) of the work over the pixels that cost any, of one or more frames;
/// 1 without such pixels. The heat map's automatic scale.
#[must_use]
pub fn work_quantile<'a>(frames: impl IntoIterator<Item = &'a [u32]>, q: f64) -> u32 {
    let mut v: Vec<u32> = frames
        .into_iter()
        .flat_map(|f| f.iter().copied().filter(|&w| w > 0))
        .collect();
    if v.is_empty() {
        return 1;
    }
    let k = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    *v.select_nth_unstable(k).1
}

/// Pixels of a tile.
const TILE_PIXELS: usize = (TILE * TILE) as usize;

/// Traces and shades a `tw` x `th` tile with its rays in batches ([`Tracer::closest_batch`],
/// [`Tracer::occluded_batch`]): the camera rays in 16x8 halves of 4x4 blocks, then the shadow
/// rays of the lit points in the same order. The same pixels as [`pixel`], one by one.
fn tile_batched<T: Tracer>(
    tracer: &T,
    stage: &Stage,
    s: &Settings,
    tile: &mut [[u8; 3]],
    (tw, th): (u32, u32),
    ray_at: impl Fn(u32, u32) -> Ray,
    c: &mut FrameCounts,
) {
    let blank = Ray::new(Vec3::ZERO, Vec3::X);
    let mut pix = [0u16; TILE_PIXELS];
    let mut rays = [blank; TILE_PIXELS];
    let mut n = 0;
    for half in 0..TILE / 8 {
        for by in 0..2 {
            for bx in 0..TILE / 4 {
                for y in 0..4 {
                    for x in 0..4 {
                        let (px, py) = (bx * 4 + x, half * 8 + by * 4 + y);
                        if px < tw && py < th {
                            pix[n] = (py * TILE + px) as u16;
                            rays[n] = ray_at(px, py);
                            n += 1;
                        }
                    }
                }
            }
        }
    }
    let mut hits = [None; TILE_PIXELS];
    tracer.closest_batch(&rays[..n], s.smooth, &mut hits[..n]);
    let mut seen = [Seen::Sky; TILE_PIXELS];
    let mut lit = [1.0f32; TILE_PIXELS];
    let mut shadow_rays = [blank; TILE_PIXELS];
    let mut shadow_of = [0u16; TILE_PIXELS];
    let mut m = 0;
    for k in 0..n {
        seen[k] = see(stage, &rays[k], hits[k]);
        if matches!(seen[k], Seen::Surface { .. }) {
            c.hits += 1;
        }
        match shadow_origin(stage, s, &rays[k], &seen[k]) {
            (Some(from), _) => {
                shadow_rays[m] = Ray::new(from, stage.light);
                shadow_of[m] = k as u16;
                m += 1;
            }
            (None, l) => lit[k] = l,
        }
    }
    c.primary += n as u64;
    c.shadow += m as u64;
    let mut occluded = [false; TILE_PIXELS];
    tracer.occluded_batch(&shadow_rays[..m], &mut occluded[..m]);
    for j in 0..m {
        lit[shadow_of[j] as usize] = if occluded[j] { 0.0 } else { 1.0 };
    }
    for k in 0..n {
        tile[pix[k] as usize] = to_srgb(color(stage, &rays[k], &seen[k], lit[k]));
    }
}

/// Draws the heat map's legend along the bottom of `img`: the colour bar from 0 to `max` with
/// ticks and numbers, and what it measures.
pub fn draw_heat_legend(img: &mut RgbImage, max: u32) {
    let (w, h) = img.dimensions();
    let scale = (h / 480).max(1);
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
    let title = "nodes + triangles per pixel (primary + shadow ray); grey: none";
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
