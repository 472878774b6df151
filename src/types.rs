//! The types every room exchanges: depth images, point sets, per-stage timings, per-call stats,
//! and the depth tolerance that makes two hits one surface. They sit below the paper rooms
//! (`nonredundant`, `epr`, `visibility_field`, `impostors`) and the floors they stand on
//! (`image`, `calibration`, `gpu`, `trace`, `io`), so that none has to reach into another.

use std::time::Instant;

use crate::camera::Camera;
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;

/// Values by name, in the order each name was first recorded: the body of [`Timings`] and
/// [`Stats`], which differ in what recording a name twice means.
#[derive(Debug, Clone, Default, PartialEq)]
struct Named(Vec<(&'static str, f64)>);

impl Named {
    /// The value of `name`, made 0 if new.
    fn entry(&mut self, name: &'static str) -> &mut f64 {
        let i = match self.0.iter().position(|(s, _)| *s == name) {
            Some(i) => i,
            None => {
                self.0.push((name, 0.0));
                self.0.len() - 1
            }
        };
        &mut self.0[i].1
    }

    fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(s, _)| *s == name).map(|&(_, v)| v)
    }

    fn iter(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.0.iter().copied()
    }
}

/// Seconds per stage of one call, in the order the stages first ran. A stage recorded twice
/// (a loop, or two passes of one kind) holds the sum.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timings(Named);

impl Timings {
    pub fn new() -> Self {
        Self::default()
    }

    /// Add `seconds` to `stage`.
    pub fn add(&mut self, stage: &'static str, seconds: f64) {
        *self.0.entry(stage) += seconds;
    }

    /// Add the seconds since `start` to `stage`.
    pub fn since(&mut self, stage: &'static str, start: Instant) {
        self.add(stage, start.elapsed().as_secs_f64());
    }

    /// Set `stage` to `seconds` (a total measured from the call's start).
    pub fn set(&mut self, stage: &'static str, seconds: f64) {
        *self.0.entry(stage) = seconds;
    }

    /// The seconds of `stage`, if it ran.
    pub fn get(&self, stage: &str) -> Option<f64> {
        self.0.get(stage)
    }

    /// Add every stage of `other`.
    pub fn merge(&mut self, other: &Timings) {
        for (s, t) in other.iter() {
            self.add(s, t);
        }
    }

    /// (stage, seconds) in order.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.0.iter()
    }
}

impl<const N: usize> From<[(&'static str, f64); N]> for Timings {
    fn from(stages: [(&'static str, f64); N]) -> Self {
        let mut t = Timings::new();
        for (s, x) in stages {
            t.add(s, x);
        }
        t
    }
}

/// What one call did, by name (points made, cells culled, bytes of buffers, ...), in the order
/// first recorded; recording a name again replaces its value. Counts are kept as f64 because
/// Python receives them as floats.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stats(Named);

impl Stats {
    pub fn new() -> Self {
        Self::default()
    }

    /// Set `name` to `value`.
    pub fn set(&mut self, name: &'static str, value: f64) {
        *self.0.entry(name) = value;
    }

    /// The value of `name`, if recorded.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.get(name)
    }

    /// Set every entry of `other` (the stats of a step this call ran).
    pub fn extend(&mut self, other: &Stats) {
        for (s, v) in other.iter() {
            self.set(s, v);
        }
    }

    /// (name, value) in order.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.0.iter()
    }
}

impl<const N: usize> From<[(&'static str, f64); N]> for Stats {
    fn from(entries: [(&'static str, f64); N]) -> Self {
        let mut s = Stats::new();
        for (k, v) in entries {
            s.set(k, v);
        }
        s
    }
}

/// Two hits whose `t` differ by at most this fraction of the larger are one surface met twice
/// (a duplicated or coplanar face): `nearest_hits` counts them once, and depth peeling makes
/// them one layer (`discretize::discretize_peeling`).
pub const SAME_HIT: f32 = 1e-5;

/// `n` images of `height`×`width`, row-major, image after image.
#[derive(Debug, Clone, Default)]
pub struct DepthImages {
    pub n: usize,
    pub width: u32,
    pub height: u32,
    /// Camera-space z (positive), +inf where no surface.
    pub depth: Vec<f32>,
    /// Scene face index, −1 where no surface.
    pub triangle: Vec<i32>,
    /// Unit world geometric normal from the triangle's winding (not flipped toward the camera);
    /// zero where no surface or the triangle is degenerate.
    pub normal: Vec<[f32; 3]>,
    /// Unit world shading normal: the vertices' normals interpolated at the sample (the file's
    /// NORMAL as posed, else area-weighted; `scene::surface`), not flipped toward the camera;
    /// zero where no surface.
    pub shading_normal: Vec<[f32; 3]>,
    /// World position of the surface point; NaN where no surface.
    pub position: Vec<[f32; 3]>,
    /// Linear base colour: the vertices' colours interpolated times the material's texture
    /// sampled for the pixel's footprint (`scene::surface`); zero where no surface.
    pub color: Vec<[f32; 3]>,
    pub cameras: Vec<Camera>,
    /// How the images were made: "conventional", "nonredundant" or "peeling".
    pub method: String,
    pub timings: Timings,
}

impl DepthImages {
    /// Give pixel `to` every field of pixel `from` of `other` (images of the same cameras).
    pub fn copy_pixel(&mut self, to: usize, other: &DepthImages, from: usize) {
        self.depth[to] = other.depth[from];
        self.triangle[to] = other.triangle[from];
        self.normal[to] = other.normal[from];
        self.shading_normal[to] = other.shading_normal[from];
        self.position[to] = other.position[from];
        self.color[to] = other.color[from];
    }

    /// Give pixel `to` every field of pixel `from` of the same images.
    pub fn move_pixel(&mut self, to: usize, from: usize) {
        self.depth[to] = self.depth[from];
        self.triangle[to] = self.triangle[from];
        self.normal[to] = self.normal[from];
        self.shading_normal[to] = self.shading_normal[from];
        self.position[to] = self.position[from];
        self.color[to] = self.color[from];
    }

    /// Make pixel `i` see nothing: depth +inf, triangle −1, zero normals and colour, NaN
    /// position.
    pub fn clear_pixel(&mut self, i: usize) {
        self.depth[i] = f32::INFINITY;
        self.triangle[i] = -1;
        self.normal[i] = [0.0; 3];
        self.shading_normal[i] = [0.0; 3];
        self.position[i] = [f32::NAN; 3];
        self.color[i] = [0.0; 3];
    }
}

/// A point set, as `discretize(method="epr")` makes it or a caller builds it.
#[derive(Debug, Clone, Default)]
pub struct Points {
    pub center: Vec<[f32; 3]>,
    /// Side of the point's square, world units.
    pub length: Vec<f32>,
    pub triangle: Vec<i32>,
    /// Unit geometric normal of the point's triangle.
    pub normal: Vec<[f32; 3]>,
    /// Unit shading normal at the point's centre (`scene::surface`).
    pub shading_normal: Vec<[f32; 3]>,
    /// Linear base colour over the point's square (`scene::surface`: its texture filtered
    /// over the square's side).
    pub color: Vec<[f32; 3]>,
    pub material: Vec<i32>,
    /// `words()` words per point: bit v % 64 of word v / 64 is set when view v may see the point.
    pub views: Vec<u64>,
    /// How many views the bit strings describe.
    pub view_count: usize,
    pub timings: Timings,
    pub stats: Stats,
}

impl Points {
    /// 64-bit words per point in `views`.
    pub fn words(&self) -> usize {
        self.view_count.div_ceil(64).max(1)
    }

    pub fn len(&self) -> usize {
        self.center.len()
    }

    pub fn is_empty(&self) -> bool {
        self.center.is_empty()
    }

    /// Check the arrays against each other and against `scene`.
    pub fn validate(&self, scene: &Scene) -> Result<()> {
        let n = self.len();
        // Normals, colours and materials are for shading, not splatting: they may be left
        // empty.
        for (name, len, optional) in [
            ("length", self.length.len(), false),
            ("triangle", self.triangle.len(), false),
            ("normal", self.normal.len(), true),
            ("shading_normal", self.shading_normal.len(), true),
            ("color", self.color.len(), true),
            ("material", self.material.len(), true),
        ] {
            if len != n && !(optional && len == 0) {
                return input_err!("points have {n} centres but {len} entries in {name}");
            }
        }
        if self.views.len() != n * self.words() {
            return input_err!(
                "points over {} views need {} visibility words each ({} in all), got {}",
                self.view_count,
                self.words(),
                n * self.words(),
                self.views.len()
            );
        }
        let t = scene.triangle_count();
        if let Some((i, &bad)) = self
            .triangle
            .iter()
            .enumerate()
            .find(|(_, &k)| k < 0 || k as usize >= t)
        {
            return input_err!("point {i} names triangle {bad}, but the scene has {t} triangles");
        }
        if let Some(i) = self
            .center
            .iter()
            .position(|c| !c.iter().all(|x| x.is_finite()))
        {
            return input_err!("point {i} has a non-finite centre {:?}", self.center[i]);
        }
        if let Some(i) = self
            .length
            .iter()
            .position(|l| !(l.is_finite() && *l >= 0.0))
        {
            return input_err!(
                "point {i} has length {}; lengths must be finite and >= 0",
                self.length[i]
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timings_add_and_stats_replace_in_first_order() {
        let mut t = Timings::from([("a", 1.0), ("b", 2.0)]);
        t.add("a", 0.5);
        t.set("b", 4.0);
        assert_eq!(t.iter().collect::<Vec<_>>(), vec![("a", 1.5), ("b", 4.0)]);

        let mut s = Stats::from([("points", 3.0), ("cells", 1.0)]);
        s.extend(&Stats::from([("cells", 7.0), ("bytes", 64.0)]));
        assert_eq!(
            s.iter().collect::<Vec<_>>(),
            vec![("points", 3.0), ("cells", 7.0), ("bytes", 64.0)]
        );
        assert_eq!(s.get("cells"), Some(7.0));
        assert_eq!(s.get("rays"), None);
    }
}
