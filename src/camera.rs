//! Camera in the OpenGL / pyrender / glTF convention: a 4×4 camera-to-world pose (f64), the
//! camera looks along −Z with +Y up, `yfov` in radians, image row 0 at the top, pixel centres at
//! +0.5. Depth is camera-space z (positive in front of the camera).

use glam::{DMat3, DMat4, DVec2, DVec3, DVec4};

use crate::error::Result;
use crate::input_err;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Vertical field of view in radians; the horizontal one follows from width / height.
    Perspective { yfov: f64 },
    /// Half-extents of the view volume in world units (glTF `xmag`, `ymag`).
    Orthographic { xmag: f64, ymag: f64 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Camera-to-world rigid transform (orthonormal rotation + translation).
    pub pose: DMat4,
    pub projection: Projection,
    pub width: u32,
    pub height: u32,
    /// Near and far planes (camera z); `None` resolves from the scene's bounds at render time.
    pub znear: Option<f64>,
    pub zfar: Option<f64>,
    pub name: Option<String>,
}

/// How far a pose's rotation may be from orthonormal before it is rejected.
const RIGID_TOL: f64 = 1e-4;

impl Camera {
    /// Build a camera from a pose, validating the pose, projection and resolution.
    pub fn new(
        pose: DMat4,
        projection: Projection,
        width: u32,
        height: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> Result<Self> {
        check_pose(&pose)?;
        if width == 0 || height == 0 {
            return input_err!("camera resolution must be positive, got {width}x{height}");
        }
        match projection {
            Projection::Perspective { yfov } if !(yfov > 0.0 && yfov < std::f64::consts::PI) => {
                return input_err!("yfov must be in (0, pi) radians, got {yfov}");
            }
            Projection::Orthographic { xmag, ymag }
                if !(xmag.is_finite() && ymag.is_finite() && xmag > 0.0 && ymag > 0.0) =>
            {
                return input_err!("xmag and ymag must be positive and finite, got {xmag}, {ymag}");
            }
            _ => {}
        }
        if let Some(n) = znear {
            if !(n.is_finite() && n > 0.0) {
                return input_err!("znear must be positive and finite, got {n}");
            }
        }
        if let Some(f) = zfar {
            if f.is_nan() || f <= znear.unwrap_or(0.0) {
                return input_err!(
                    "zfar must be greater than znear, got zfar={f}, znear={znear:?}"
                );
            }
        }
        if zfar == Some(f64::INFINITY) && matches!(projection, Projection::Orthographic { .. }) {
            return input_err!("an orthographic camera needs a finite zfar");
        }
        Ok(Self {
            pose,
            projection,
            width,
            height,
            znear,
            zfar,
            name: None,
        })
    }

    /// A perspective camera at `eye` looking at `target`.
    #[allow(clippy::too_many_arguments)]
    pub fn look_at(
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        yfov: f64,
        width: u32,
        height: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> Result<Self> {
        let pose = look_at_pose(eye, target, up)?;
        Self::new(
            pose,
            Projection::Perspective { yfov },
            width,
            height,
            znear,
            zfar,
        )
    }

    /// The six 90° faces of a cube map at `center`, in the OpenGL / glTF face order
    /// +X, −X, +Y, −Y, +Z, −Z, with OpenGL's face up vectors (−Y, −Y, +Z, −Z, −Y, −Y).
    /// Our images have row 0 at the top, so uploading one as a GL cube-map face needs a
    /// vertical flip (GL stores a face's first row at its bottom).
    pub fn cube(
        center: DVec3,
        resolution: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> Result<Vec<Self>> {
        let faces = [
            (DVec3::X, DVec3::NEG_Y),
            (DVec3::NEG_X, DVec3::NEG_Y),
            (DVec3::Y, DVec3::Z),
            (DVec3::NEG_Y, DVec3::NEG_Z),
            (DVec3::Z, DVec3::NEG_Y),
            (DVec3::NEG_Z, DVec3::NEG_Y),
        ];
        faces
            .iter()
            .map(|&(dir, up)| {
                let yfov = std::f64::consts::FRAC_PI_2;
                Self::look_at(
                    center,
                    center + dir,
                    up,
                    yfov,
                    resolution,
                    resolution,
                    znear,
                    zfar,
                )
            })
            .collect()
    }

    /// Which face of `Camera::cube` a direction from the cube's centre lands on: the face of
    /// its largest axis (ties go to x, then y).
    pub fn cube_face(dir: DVec3) -> usize {
        let a = dir.abs();
        let (axis, positive) = if a.x >= a.y && a.x >= a.z {
            (0, dir.x >= 0.0)
        } else if a.y >= a.z {
            (1, dir.y >= 0.0)
        } else {
            (2, dir.z >= 0.0)
        };
        2 * axis + usize::from(!positive)
    }

    pub fn eye(&self) -> DVec3 {
        self.pose.w_axis.truncate()
    }
    /// Unit world direction the camera looks along (its −Z axis).
    pub fn forward(&self) -> DVec3 {
        -self.pose.z_axis.truncate()
    }
    /// World-to-camera rotation (transpose of the pose's rotation).
    pub fn world_to_camera_rotation(&self) -> DMat3 {
        DMat3::from_mat4(self.pose).transpose()
    }

    /// World size of one pixel (its height) on the plane facing the camera at camera depth
    /// `depth`: `depth · 2 tan(yfov/2) / height` (perspective) or `2 ymag / height`
    /// (orthographic).
    pub fn pixel_footprint(&self, depth: f64) -> f64 {
        let h = self.half_extents();
        match self.projection {
            Projection::Perspective { .. } => depth * 2.0 * h.y / self.height as f64,
            Projection::Orthographic { .. } => 2.0 * h.y / self.height as f64,
        }
    }

    /// The camera offset by half a pixel in both directions (non-redundant-rendering.txt
    /// Algorithm 4, step 1): same pose and pixel size, (width+1)×(height+1) pixels, so that its
    /// pixel (x, y) centre lies on this camera's pixel corner (x, y).
    pub fn corner_camera(&self) -> Result<Camera> {
        let (w, h) = (self.width as f64, self.height as f64);
        let projection = match self.projection {
            Projection::Perspective { yfov } => Projection::Perspective {
                yfov: 2.0 * ((yfov * 0.5).tan() * (h + 1.0) / h).atan(),
            },
            Projection::Orthographic { xmag, ymag } => Projection::Orthographic {
                xmag: xmag * (w + 1.0) / w,
                ymag: ymag * (h + 1.0) / h,
            },
        };
        let mut c = Camera::new(
            self.pose,
            projection,
            self.width + 1,
            self.height + 1,
            self.znear,
            self.zfar,
        )?;
        c.name = self.name.clone();
        Ok(c)
    }

    /// Camera-space half extents of the image plane at z = −1 (perspective) or of the view
    /// volume (orthographic).
    fn half_extents(&self) -> DVec2 {
        let aspect = self.width as f64 / self.height as f64;
        match self.projection {
            Projection::Perspective { yfov } => {
                let t = (yfov * 0.5).tan();
                DVec2::new(t * aspect, t)
            }
            Projection::Orthographic { xmag, ymag } => DVec2::new(xmag, ymag),
        }
    }

    /// World point → (pixel x, pixel y, depth). Depth is camera-space z (positive in front);
    /// points at or behind a perspective camera's plane give non-finite pixel coordinates.
    pub fn project(&self, p: DVec3) -> (DVec2, f64) {
        self.projector().project(p)
    }

    /// The view volume as planes (unit inward normal, offset), inside meaning `n·p + d >= 0`
    /// for points `p` relative to `origin`: the near plane at camera depth `near` (0: the eye's
    /// plane) and the four sides, their extents scaled by `margin` (1: the exact frustum).
    pub fn frustum_planes(&self, margin: f64, near: f64, origin: DVec3) -> Vec<(DVec3, f64)> {
        let e = self.eye() - origin;
        let r = self.world_to_camera_rotation();
        // Camera axes in world space: rows of the world-to-camera rotation.
        let (right, up, fwd) = (r.row(0), r.row(1), -r.row(2));
        let mut planes = vec![(fwd, -fwd.dot(e) - near)];
        match self.projection {
            Projection::Perspective { yfov } => {
                let ty = (yfov / 2.0).tan() * margin;
                let tx = ty * self.width as f64 / self.height as f64;
                // Inside: |x| <= tx·z, |y| <= ty·z in camera space, z along fwd.
                for (axis, t) in [(right, tx), (up, ty)] {
                    for sign in [1.0, -1.0] {
                        let n = (fwd * t - axis * sign).normalize();
                        planes.push((n, -n.dot(e)));
                    }
                }
            }
            Projection::Orthographic { xmag, ymag } => {
                for (axis, h) in [(right, xmag * margin), (up, ymag * margin)] {
                    for sign in [1.0, -1.0] {
                        let n = -axis * sign;
                        planes.push((n, h - n.dot(e)));
                    }
                }
            }
        }
        planes
    }

    /// Pixel position and depth (camera z) → world point; the inverse of `project`.
    pub fn unproject(&self, pixel: DVec2, depth: f64) -> DVec3 {
        let (origin, dir) = self.ray_z1(pixel);
        origin + dir * depth
    }

    /// The ray through a pixel position, with a direction whose camera-space z is −1, so that
    /// `origin + t·dir` lies at depth `t`.
    pub fn ray_z1(&self, pixel: DVec2) -> (DVec3, DVec3) {
        self.projector().ray_z1(pixel)
    }

    /// [`Camera::project`] and [`Camera::ray_z1`] with the rotations and the half extents
    /// worked out once, for loops over many pixels or points (the same arithmetic, so the same
    /// answers to the bit).
    pub fn projector(&self) -> Projector {
        let to_world = DMat3::from_mat4(self.pose);
        Projector {
            to_camera: to_world.transpose(),
            to_world,
            eye: self.eye(),
            half: self.half_extents(),
            size: DVec2::new(self.width as f64, self.height as f64),
            perspective: matches!(self.projection, Projection::Perspective { .. }),
        }
    }

    /// Near and far planes for rendering `bounds`: the explicit ones when set, otherwise the
    /// range of camera z over the bounds' corners, widened by 1% (znear at least far·1e-7, so
    /// a camera inside the bounds still sees what is near it).
    pub fn clip_range(&self, bounds: [[f32; 3]; 2]) -> (f64, f64) {
        let rot = self.world_to_camera_rotation();
        let eye = self.eye();
        let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..8 {
            let corner = DVec3::new(
                bounds[i & 1][0] as f64,
                bounds[(i >> 1) & 1][1] as f64,
                bounds[(i >> 2) & 1][2] as f64,
            );
            let z = -(rot * (corner - eye)).z;
            dmin = dmin.min(z);
            dmax = dmax.max(z);
        }
        let far = self
            .zfar
            .unwrap_or((dmax * 1.01).max(f64::MIN_POSITIVE * 1e10));
        let near_floor = if far.is_finite() {
            far * 1e-7
        } else {
            dmax.abs().max(1.0) * 1e-7
        };
        let near = self.znear.unwrap_or((dmin * 0.99).max(near_floor));
        let far = if far > near { far } else { near * 2.0 };
        (near, far)
    }

    /// The projection matrix to wgpu clip space with reversed depth (near → 1, far → 0;
    /// an infinite far plane is allowed for perspective). Reversed depth keeps f32 depth-test
    /// precision roughly relative over the whole range, so far/near ratios of 1e7 still order.
    pub fn projection_matrix(&self, near: f64, far: f64) -> DMat4 {
        let h = self.half_extents();
        match self.projection {
            Projection::Perspective { .. } => {
                let (a, b) = if far.is_finite() {
                    (near / (far - near), near * far / (far - near))
                } else {
                    (0.0, near)
                };
                DMat4::from_cols(
                    DVec4::new(1.0 / h.x, 0.0, 0.0, 0.0),
                    DVec4::new(0.0, 1.0 / h.y, 0.0, 0.0),
                    DVec4::new(0.0, 0.0, a, -1.0),
                    DVec4::new(0.0, 0.0, b, 0.0),
                )
            }
            Projection::Orthographic { .. } => DMat4::from_cols(
                DVec4::new(1.0 / h.x, 0.0, 0.0, 0.0),
                DVec4::new(0.0, 1.0 / h.y, 0.0, 0.0),
                DVec4::new(0.0, 0.0, 1.0 / (far - near), 0.0),
                DVec4::new(0.0, 0.0, far / (far - near), 1.0),
            ),
        }
    }

    /// World → camera transform for points given relative to `origin` (the scene centre):
    /// translation is formed in f64 so that scenes far from the world origin keep full f32
    /// precision on the GPU.
    pub fn view_matrix_relative(&self, origin: DVec3) -> DMat4 {
        let rot = self.world_to_camera_rotation();
        let t = -(rot * (self.eye() - origin));
        DMat4::from_cols(
            rot.x_axis.extend(0.0),
            rot.y_axis.extend(0.0),
            rot.z_axis.extend(0.0),
            t.extend(1.0),
        )
    }

    /// A camera between `cameras`: the weighted mean of their viewpoints, and their orientations
    /// averaged as unit quaternions (signs aligned to the first, weighted sum normalised: exact
    /// for two cameras up to the slerp/nlerp difference, a good mean for nearby orientations).
    /// Projection, resolution and clip planes come from the first camera. Weights must be
    /// non-negative with a positive sum; they are normalised.
    pub fn blend(cameras: &[Camera], weights: &[f64]) -> Result<Camera> {
        let total: f64 = weights.iter().sum();
        if cameras.is_empty()
            || cameras.len() != weights.len()
            || weights.iter().any(|w| w.is_nan() || *w < 0.0)
            || !(total > 0.0 && total.is_finite())
        {
            return input_err!(
                "blend needs one non-negative weight per camera with a positive sum, got {} \
                 cameras and weights {weights:?}",
                cameras.len()
            );
        }
        let q0 = glam::DQuat::from_mat3(&DMat3::from_mat4(cameras[0].pose));
        let mut q = glam::DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
        let mut eye = DVec3::ZERO;
        for (c, &w) in cameras.iter().zip(weights) {
            let w = w / total;
            let qi = glam::DQuat::from_mat3(&DMat3::from_mat4(c.pose));
            let qi = if qi.dot(q0) < 0.0 { -qi } else { qi };
            q += qi * w;
            eye += c.eye() * w;
        }
        let q = q.normalize();
        let pose = DMat4::from_rotation_translation(q, eye);
        let first = &cameras[0];
        Self::new(
            pose,
            first.projection,
            first.width,
            first.height,
            first.znear,
            first.zfar,
        )
    }

    /// A copy with another resolution.
    pub fn with_resolution(&self, width: u32, height: u32) -> Result<Self> {
        let mut c = Self::new(
            self.pose,
            self.projection,
            width,
            height,
            self.znear,
            self.zfar,
        )?;
        c.name = self.name.clone();
        Ok(c)
    }
}

/// Camera-to-world pose at `eye` looking at `target`, +Y of the image along `up`'s projection.
pub fn look_at_pose(eye: DVec3, target: DVec3, up: DVec3) -> Result<DMat4> {
    if !(eye.is_finite() && target.is_finite() && up.is_finite()) {
        return input_err!("look_at needs finite eye, target and up, got {eye}, {target}, {up}");
    }
    let back = eye - target;
    if back.length() == 0.0 {
        return input_err!("look_at: eye and target are the same point {eye}");
    }
    let z = back.normalize();
    let x = up.cross(z);
    if x.length() <= 1e-12 * up.length() {
        return input_err!("look_at: up {up} is parallel to the view direction {}", -z);
    }
    let x = x.normalize();
    let y = z.cross(x);
    Ok(DMat4::from_cols(
        x.extend(0.0),
        y.extend(0.0),
        z.extend(0.0),
        eye.extend(1.0),
    ))
}

/// A pose must be finite, with an orthonormal right-handed rotation and a (0, 0, 0, 1) last row.
pub fn check_pose(pose: &DMat4) -> Result<()> {
    if !pose.is_finite() {
        return input_err!("camera pose must be finite, got {pose}");
    }
    let row3 = pose.row(3);
    if (row3 - DVec4::W).abs().max_element() > RIGID_TOL {
        return input_err!("camera pose's last row must be (0, 0, 0, 1), got {row3}");
    }
    let r = DMat3::from_mat4(*pose);
    let err = (r.transpose() * r - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, RIGID_TOL);
    if !err || (r.determinant() - 1.0).abs() > RIGID_TOL {
        return input_err!(
            "camera pose's rotation must be orthonormal and right-handed (no scale or shear); \
             got determinant {}",
            r.determinant()
        );
    }
    Ok(())
}

/// Remove scale (and small shear) from a world transform so it can serve as a camera pose:
/// Gram–Schmidt on the rotation columns, keeping −Z (the view direction) exact.
pub fn rigid_from(m: DMat4) -> DMat4 {
    let z = m.z_axis.truncate().normalize_or(DVec3::Z);
    let y0 = m.y_axis.truncate();
    let x = y0.cross(z).normalize_or(DVec3::X);
    let y = z.cross(x);
    DMat4::from_cols(
        x.extend(0.0),
        y.extend(0.0),
        z.extend(0.0),
        m.w_axis.truncate().extend(1.0),
    )
}

/// A camera's projection with its per-call work hoisted: see [`Camera::projector`].
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    to_camera: DMat3,
    to_world: DMat3,
    eye: DVec3,
    half: DVec2,
    size: DVec2,
    perspective: bool,
}

impl Projector {
    /// See [`Camera::project`].
    pub fn project(&self, p: DVec3) -> (DVec2, f64) {
        let c = self.to_camera * (p - self.eye);
        let depth = -c.z;
        let ndc = if self.perspective {
            DVec2::new(c.x, c.y) / (depth * self.half)
        } else {
            DVec2::new(c.x, c.y) / self.half
        };
        let px = DVec2::new(
            (ndc.x + 1.0) * 0.5 * self.size.x,
            (1.0 - ndc.y) * 0.5 * self.size.y,
        );
        (px, depth)
    }

    /// [`Projector::project`] of the point `q / w` given in homogeneous form, as homogeneous
    /// pixel coordinates `(x·k, y·k, k)`: affine in `(q, w)`, so that along a line of points
    /// (a row of another view's pixels meeting a plane) they are affine in the parameter and
    /// only the division is left per point.
    pub fn project_homogeneous(&self, q: DVec3, w: f64) -> DVec3 {
        let c = self.to_camera * (q - self.eye * w);
        let k = if self.perspective { -c.z } else { w };
        DVec3::new(
            (c.x / self.half.x + k) * 0.5 * self.size.x,
            (k - c.y / self.half.y) * 0.5 * self.size.y,
            k,
        )
    }

    /// See [`Camera::ray_z1`].
    pub fn ray_z1(&self, pixel: DVec2) -> (DVec3, DVec3) {
        // Normalised device coordinates: x right, y up, in [−1, 1]; pixel centres at +0.5.
        let ndc = DVec2::new(
            2.0 * pixel.x / self.size.x - 1.0,
            1.0 - 2.0 * pixel.y / self.size.y,
        );
        let h = self.half;
        if self.perspective {
            let d = DVec3::new(ndc.x * h.x, ndc.y * h.y, -1.0);
            (self.eye, self.to_world * d)
        } else {
            let o = DVec3::new(ndc.x * h.x, ndc.y * h.y, 0.0);
            (self.eye + self.to_world * o, self.to_world * DVec3::NEG_Z)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::look_at(
            DVec3::new(1.0, 2.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            0.8,
            64,
            48,
            None,
            None,
        )
        .unwrap()
    }

    #[test]
    fn corner_camera_centres_lie_on_pixel_corners() {
        let c = cam();
        let k = c.corner_camera().unwrap();
        for (x, y) in [(0.0, 0.0), (3.0, 5.0), (c.width as f64, c.height as f64)] {
            let (o1, d1) = c.ray_z1(DVec2::new(x, y));
            let (o2, d2) = k.ray_z1(DVec2::new(x + 0.5, y + 0.5));
            assert!((o1 - o2).length() < 1e-12 && (d1 - d2).length() < 1e-12);
        }
        assert!((k.pixel_footprint(2.0) - c.pixel_footprint(2.0)).abs() < 1e-12);
    }

    #[test]
    fn homogeneous_projection_is_the_projection() {
        let ortho = Camera::new(
            cam().pose,
            Projection::Orthographic {
                xmag: 1.5,
                ymag: 1.0,
            },
            64,
            48,
            None,
            None,
        )
        .unwrap();
        for c in [cam(), ortho] {
            let p = c.projector();
            for (q, w) in [
                (DVec3::new(0.3, -0.2, 0.1), 1.0),
                (DVec3::new(-1.0, 2.0, 0.5), -2.5),
            ] {
                let h = p.project_homogeneous(q, w);
                let (px, _) = c.project(q / w);
                assert!(
                    (DVec2::new(h.x, h.y) / h.z - px).length() < 1e-9,
                    "{h} {px}"
                );
                assert_eq!(p.ray_z1(px), c.ray_z1(px));
            }
        }
    }

    #[test]
    fn project_unproject_round_trip() {
        let c = cam();
        let p = DVec3::new(0.3, -0.2, 0.1);
        let (px, d) = c.project(p);
        assert!((c.unproject(px, d) - p).length() < 1e-12);
    }

    #[test]
    fn centre_pixel_looks_at_target() {
        let c = cam();
        let (px, _) = c.project(DVec3::ZERO);
        assert!((px - DVec2::new(32.0, 24.0)).length() < 1e-9);
        // Row 0 is the top: a point above the target projects to a smaller row.
        let (up, _) = c.project(DVec3::new(0.0, 0.5, 0.0));
        assert!(up.y < 24.0);
    }

    #[test]
    fn cube_faces_follow_gl_order() {
        let faces = Camera::cube(DVec3::ZERO, 8, None, None).unwrap();
        let dirs: Vec<DVec3> = faces.iter().map(|c| c.forward()).collect();
        let want = [
            DVec3::X,
            DVec3::NEG_X,
            DVec3::Y,
            DVec3::NEG_Y,
            DVec3::Z,
            DVec3::NEG_Z,
        ];
        for (d, w) in dirs.iter().zip(want) {
            assert!((*d - w).length() < 1e-12);
        }
    }

    #[test]
    fn rejects_scaled_pose() {
        let pose = DMat4::from_scale(DVec3::splat(2.0));
        assert!(Camera::new(
            pose,
            Projection::Perspective { yfov: 1.0 },
            4,
            4,
            None,
            None
        )
        .is_err());
    }

    #[test]
    fn reversed_depth_maps_near_to_one_and_far_to_zero() {
        let c = cam();
        let m = c.projection_matrix(0.5, 100.0);
        let ndc = |d: f64| {
            let v = m * DVec4::new(0.0, 0.0, -d, 1.0);
            v.z / v.w
        };
        assert!((ndc(0.5) - 1.0).abs() < 1e-12 && ndc(100.0).abs() < 1e-12);
    }
}
