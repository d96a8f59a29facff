//! The procedural ground-truth world: a textured ground plane, a back wall, boxes and spheres at
//! several depths, lit by a sun with hard shadows and a sky-dome ambient term.
//!
//! World frame: y up, the cameras look roughly along −z. Colours are linear RGB. The world is an
//! analytic surface model, deliberately *not* a Gaussian set, so a trainer cannot reproduce it
//! exactly by copying parameters.

use crate::geom::V3;
use crate::texture::{Pattern, fbm, hash3, unit};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// Surface appearance: a two-colour pattern times a fine multi-octave brightness detail.
#[derive(Clone, Debug)]
pub struct Material {
    pub pattern: Pattern,
    pub colour_a: V3,
    pub colour_b: V3,
    /// Feature size (metres) of the fine fBm detail that makes sharp images sharp.
    pub detail_size: f32,
    pub seed: u32,
}

impl Material {
    /// Linear albedo at world point `p`.
    pub fn albedo(&self, p: V3) -> V3 {
        let m = self.pattern.eval(p, self.seed);
        let base = self.colour_a * (1.0 - m) + self.colour_b * m;
        let detail = fbm(p * (1.0 / self.detail_size), 3, self.seed ^ 0xa511_e9b3);
        base * (0.55 + 0.9 * detail)
    }
}

/// Geometric primitive.
#[derive(Clone, Debug)]
pub enum Shape {
    /// Plane `normal · p = offset` (normal is unit length and faces the cameras).
    Plane {
        normal: V3,
        offset: f32,
    },
    Sphere {
        centre: V3,
        radius: f32,
    },
    /// Box with half extents `half`, rotated by `yaw` radians about the vertical axis.
    Box {
        centre: V3,
        half: V3,
        cos_yaw: f32,
        sin_yaw: f32,
    },
}

/// One object of the world.
#[derive(Clone, Debug)]
pub struct Object {
    pub shape: Shape,
    pub material: Material,
}

/// Nearest intersection along a ray.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Ray parameter (distance for a unit direction).
    pub t: f32,
    pub normal: V3,
    pub object: usize,
}

/// The full scene description. Public so tests of other crates can ray-cast ground truth.
#[derive(Clone, Debug)]
pub struct World {
    pub objects: Vec<Object>,
    /// Unit direction towards the sun.
    pub sun_dir: V3,
    pub sun_colour: V3,
    pub sky_colour: V3,
    /// Point the camera path looks at; the scene's centre of interest.
    pub target: V3,
    sky_seed: u32,
}

/// Rays start this far from a surface to avoid self-intersection ("shadow acne").
const EPS: f32 = 1e-3;

impl Shape {
    fn intersect(&self, o: V3, d: V3) -> Option<(f32, V3)> {
        match *self {
            Shape::Plane { normal, offset } => {
                let den = normal.dot(d);
                if den.abs() < 1e-9 {
                    return None;
                }
                let t = (offset - normal.dot(o)) / den;
                (t > EPS).then_some((t, if den < 0.0 { normal } else { -normal }))
            }
            Shape::Sphere { centre, radius } => {
                let oc = o - centre;
                let b = oc.dot(d);
                let c = oc.dot(oc) - radius * radius;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                let t = if -b - s > EPS { -b - s } else { -b + s };
                (t > EPS).then(|| (t, (o + d * t - centre) * (1.0 / radius)))
            }
            Shape::Box {
                centre,
                half,
                cos_yaw,
                sin_yaw,
            } => {
                // Into the box frame: rotate by −yaw about y.
                let to_local = |v: V3| {
                    V3::new(
                        cos_yaw * v.x - sin_yaw * v.z,
                        v.y,
                        sin_yaw * v.x + cos_yaw * v.z,
                    )
                };
                let lo = to_local(o - centre);
                let ld = to_local(d);
                let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
                let (mut axis0, mut axis1) = (0usize, 0usize);
                for a in 0..3 {
                    let (oa, da, ha) = (lo.get(a), ld.get(a), half.get(a));
                    if da.abs() < 1e-12 {
                        if oa.abs() > ha {
                            return None;
                        }
                        continue;
                    }
                    let (mut ta, mut tb) = ((-ha - oa) / da, (ha - oa) / da);
                    if ta > tb {
                        std::mem::swap(&mut ta, &mut tb);
                    }
                    if ta > t0 {
                        t0 = ta;
                        axis0 = a;
                    }
                    if tb < t1 {
                        t1 = tb;
                        axis1 = a;
                    }
                }
                if t0 > t1 {
                    return None;
                }
                let (t, axis) = if t0 > EPS { (t0, axis0) } else { (t1, axis1) };
                if t <= EPS {
                    return None;
                }
                let sign = (lo.get(axis) + ld.get(axis) * t).signum();
                let mut n = [0.0f32; 3];
                n[axis] = sign;
                // Back to world: rotate by +yaw about y.
                let nw = V3::new(
                    cos_yaw * n[0] + sin_yaw * n[2],
                    n[1],
                    -sin_yaw * n[0] + cos_yaw * n[2],
                );
                Some((t, nw))
            }
        }
    }
}

fn hsv(h: f32, s: f32, v: f32) -> V3 {
    let h6 = (h.rem_euclid(1.0)) * 6.0;
    let c = v * s;
    let x = c * (1.0 - ((h6 % 2.0) - 1.0).abs());
    let (r, g, b) = match h6 as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    // Squaring maps perceptual-ish values to linear reflectance.
    let lin = |u: f32| (u + m) * (u + m);
    V3::new(lin(r), lin(g), lin(b))
}

fn random_material(rng: &mut ChaCha8Rng, scale: f32) -> Material {
    let pattern = match rng.random_range(0..4u32) {
        0 => Pattern::Checker {
            size: scale * rng.random_range(0.6..1.4f32),
        },
        1 => {
            let a = rng.random_range(0.0..std::f32::consts::PI);
            Pattern::Stripes {
                dir: V3::new(a.cos(), rng.random_range(-0.5..0.5f32), a.sin()).normalized(),
                period: scale * rng.random_range(0.8..2.0f32),
            }
        }
        2 => Pattern::Blobs {
            cell: scale * rng.random_range(0.8..1.6f32),
        },
        _ => Pattern::Noise {
            size: scale * rng.random_range(0.8..2.0f32),
        },
    };
    let h = rng.random_range(0.0..1.0f32);
    Material {
        pattern,
        colour_a: hsv(h, rng.random_range(0.3..0.9), rng.random_range(0.55..0.95)),
        colour_b: hsv(
            h + rng.random_range(0.15..0.6),
            rng.random_range(0.2..0.8),
            rng.random_range(0.2..0.6),
        ),
        detail_size: rng.random_range(0.05..0.12),
        seed: rng.random::<u32>(),
    }
}

impl World {
    /// A random world: ground, back wall and `n_objects` boxes/spheres, placed without overlap
    /// in front of the wall at depths spread over the scene.
    pub fn random(rng: &mut ChaCha8Rng, n_objects: usize) -> World {
        let mut objects = vec![
            Object {
                shape: Shape::Plane {
                    normal: V3::new(0.0, 1.0, 0.0),
                    offset: 0.0,
                },
                material: random_material(rng, 0.6),
            },
            Object {
                shape: Shape::Plane {
                    normal: V3::new(0.0, 0.0, 1.0),
                    offset: -4.0,
                },
                material: random_material(rng, 0.7),
            },
        ];
        let mut placed: Vec<(f32, f32, f32)> = Vec::new();
        let mut attempts = 0;
        while placed.len() < n_objects && attempts < 1000 {
            attempts += 1;
            let size = rng.random_range(0.25..0.7f32);
            let x = rng.random_range(-2.3..2.3f32);
            let z = rng.random_range(-3.4..0.6f32);
            let clear = placed.iter().all(|&(px, pz, ps)| {
                let d = ((px - x).powi(2) + (pz - z).powi(2)).sqrt();
                d > 1.5 * (ps + size)
            });
            if !clear {
                continue;
            }
            placed.push((x, z, size));
            let shape = if placed.len() % 2 == 1 {
                let tall = rng.random_range(1.0..2.5f32);
                let yaw = rng.random_range(0.0..std::f32::consts::FRAC_PI_2);
                Shape::Box {
                    centre: V3::new(x, size * tall, z),
                    half: V3::new(size, size * tall, size * rng.random_range(0.6..1.2f32)),
                    cos_yaw: yaw.cos(),
                    sin_yaw: yaw.sin(),
                }
            } else {
                let lift = rng.random_range(0.0..0.5f32);
                Shape::Sphere {
                    centre: V3::new(x, size * (1.0 + lift), z),
                    radius: size,
                }
            };
            objects.push(Object {
                shape,
                material: random_material(rng, 0.25),
            });
        }
        let az = rng.random_range(-1.0..1.0f32);
        World {
            objects,
            sun_dir: V3::new(az, 1.4, 0.8).normalized(),
            sun_colour: V3::new(0.75, 0.7, 0.62),
            sky_colour: V3::new(0.14, 0.17, 0.22),
            target: V3::new(0.0, 0.6, -1.4),
            sky_seed: rng.random::<u32>(),
        }
    }

    /// Nearest hit along the ray `o + t·d` (d unit length).
    pub fn intersect(&self, o: V3, d: V3) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, obj) in self.objects.iter().enumerate() {
            if let Some((t, normal)) = obj.shape.intersect(o, d)
                && best.is_none_or(|b| t < b.t)
            {
                best = Some(Hit {
                    t,
                    normal,
                    object: i,
                });
            }
        }
        best
    }

    fn occluded(&self, o: V3, d: V3) -> bool {
        self.objects
            .iter()
            .any(|obj| obj.shape.intersect(o, d).is_some())
    }

    /// Linear radiance seen along a ray: Lambertian surfaces under sun + sky, or the sky itself.
    pub fn radiance(&self, o: V3, d: V3) -> V3 {
        match self.intersect(o, d) {
            Some(hit) => {
                let p = o + d * hit.t;
                let albedo = self.objects[hit.object].material.albedo(p);
                let cos_sun = hit.normal.dot(self.sun_dir).max(0.0);
                let lit = if cos_sun > 0.0 && !self.occluded(p + hit.normal * EPS, self.sun_dir) {
                    cos_sun
                } else {
                    0.0
                };
                // Hemispherical sky term: faces pointing up see more sky.
                let sky = self.sky_colour * (0.6 + 0.4 * hit.normal.y) * 2.0;
                albedo.mul_elem(sky + self.sun_colour * lit)
            }
            None => {
                let clouds = fbm(d * 3.0, 4, self.sky_seed);
                let up = d.y.max(0.0);
                V3::new(0.45, 0.6, 0.85) * (0.7 + 0.3 * up) * (0.6 + 0.6 * clouds)
            }
        }
    }
}

/// Deterministic sub-pixel jitter in [0, 1)² for sample `k` of pixel (x, y): the same for every
/// frame, so sub-frames differ only by camera motion (no sampling flicker in the events).
pub fn pixel_jitter(x: u32, y: u32, k: u32, seed: u32) -> (f32, f32) {
    let h = hash3(x as i32, y as i32, k as i32, seed);
    (unit(h), unit(hash3(k as i32, x as i32, y as i32, h)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn shapes_intersect_where_expected() {
        let sphere = Shape::Sphere {
            centre: V3::new(0.0, 0.0, -5.0),
            radius: 1.0,
        };
        let (t, n) = sphere
            .intersect(V3::default(), V3::new(0.0, 0.0, -1.0))
            .unwrap();
        assert!((t - 4.0).abs() < 1e-5 && (n.z - 1.0).abs() < 1e-5);
        assert!(
            sphere
                .intersect(V3::default(), V3::new(0.0, 1.0, 0.0))
                .is_none()
        );

        let yaw = std::f32::consts::FRAC_PI_4;
        let boxed = Shape::Box {
            centre: V3::new(0.0, 0.0, -5.0),
            half: V3::new(1.0, 1.0, 1.0),
            cos_yaw: yaw.cos(),
            sin_yaw: yaw.sin(),
        };
        // A cube turned by 45° presents its vertical edge at distance 5 − √2.
        let (t, n) = boxed
            .intersect(V3::new(0.0, 0.5, 0.0), V3::new(0.0, 0.0, -1.0))
            .unwrap();
        assert!((t - (5.0 - 2f32.sqrt())).abs() < 1e-4, "t = {t}");
        assert!((n.norm() - 1.0).abs() < 1e-5 && n.z > 0.5);

        let plane = Shape::Plane {
            normal: V3::new(0.0, 1.0, 0.0),
            offset: 0.0,
        };
        let (t, n) = plane
            .intersect(V3::new(0.0, 2.0, 0.0), V3::new(0.0, -1.0, 0.0))
            .unwrap();
        assert!((t - 2.0).abs() < 1e-6 && n.y == 1.0);
    }

    proptest::proptest! {
        /// A ray aimed at any interior point of any turned box hits its surface, from outside,
        /// with a unit normal facing the ray.
        #[test]
        fn rays_at_a_box_hit_its_surface(
            c in proptest::array::uniform3(-3.0f32..3.0),
            h in proptest::array::uniform3(0.1f32..1.5),
            yaw in 0.0f32..6.3,
            aim in proptest::array::uniform3(-0.95f32..0.95),
            from in proptest::array::uniform3(-1.0f32..1.0),
        ) {
            let (centre, half) = (V3::new(c[0], c[1], c[2]), V3::new(h[0], h[1], h[2]));
            let shape = Shape::Box { centre, half, cos_yaw: yaw.cos(), sin_yaw: yaw.sin() };
            let to_world = |v: V3| V3::new(yaw.cos() * v.x + yaw.sin() * v.z, v.y, -yaw.sin() * v.x + yaw.cos() * v.z);
            let target = centre + to_world(V3::new(aim[0] * h[0], aim[1] * h[1], aim[2] * h[2]));
            let dir_raw = V3::new(from[0], from[1], from[2]);
            proptest::prop_assume!(dir_raw.norm() > 0.1);
            let origin = centre + dir_raw.normalized() * 10.0;
            let d = (target - origin).normalized();
            let (t, n) = shape.intersect(origin, d).expect("must hit");
            let local = |v: V3| V3::new(yaw.cos() * v.x - yaw.sin() * v.z, v.y, yaw.sin() * v.x + yaw.cos() * v.z);
            let p = local(origin + d * t - centre);
            let q = (p.x / h[0]).abs().max((p.y / h[1]).abs()).max((p.z / h[2]).abs());
            proptest::prop_assert!((q - 1.0).abs() < 1e-3, "hit point not on the surface: {q}");
            proptest::prop_assert!(t <= (target - origin).norm() + 1e-3);
            proptest::prop_assert!((n.norm() - 1.0).abs() < 1e-5 && n.dot(d) < 0.0);
        }
    }

    #[test]
    fn world_has_objects_and_shadows() {
        let world = World::random(&mut ChaCha8Rng::seed_from_u64(3), 6);
        assert_eq!(world.objects.len(), 8);
        // Looking straight down at the ground from above hits the ground or an object.
        assert!(
            world
                .intersect(V3::new(0.5, 5.0, -1.0), V3::new(0.0, -1.0, 0.0))
                .is_some()
        );
        // Somewhere on the ground near an object a sun ray is blocked.
        let blocked = (0..400).any(|i| {
            let p = V3::new(
                -2.5 + 0.0125 * i as f32,
                1e-3,
                -1.4 + ((i % 20) as f32 - 10.0) * 0.15,
            );
            world.occluded(p, world.sun_dir)
        });
        assert!(blocked);
    }
}
