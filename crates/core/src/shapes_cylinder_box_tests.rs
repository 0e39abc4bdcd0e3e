//! [`cylinder_box_pair`] (the closed-form closest pair of a cylinder's core and a box's core)
//! against today's answer, GJK refined by [`exact_pair`], and against an analytic truth of its
//! own (the support points along its normal).

use super::*;
use rand::{Rng, SeedableRng};

/// A random unit vector.
fn unit(rng: &mut rand_pcg::Pcg64Mcg) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

/// A random axis for the cylinder in the box's frame: skewed (any direction), parallel to
/// a face (one component 0), parallel to an edge (two components 0), or nearly so (one or two
/// components of 1e-3 to 1e-9).
fn axis(rng: &mut rand_pcg::Pcg64Mcg) -> Vector3<f64> {
    let mut u = unit(rng);
    match rng.random_range(0..5) {
        0 | 1 => {}
        2 => u[rng.random_range(0..3)] = 0.0,
        3 => {
            let keep = rng.random_range(0..3);
            for i in 0..3 {
                if i != keep {
                    u[i] = 0.0;
                }
            }
        }
        _ => {
            let tiny = 10f64.powf(rng.random_range(-9.0..-3.0));
            let i = rng.random_range(0..3);
            u[i] = tiny.copysign(u[i]);
            if rng.random_bool(0.5) {
                u[(i + 1) % 3] = (tiny * rng.random_range(0.1..10.0)).copysign(u[(i + 1) % 3]);
            }
        }
    }
    u.normalize()
}

/// `min` over the core `piece` at `pose` of `x·dir` (its support point along `−dir`).
fn lowest(piece: &Piece, pose: &Isometry3<f64>, dir: &Vector3<f64>) -> f64 {
    let map = piece.core.as_support_map().expect("support map");
    let down = Unit::new_normalize(-dir);
    map.support_point(pose, &down).coords.dot(dir)
}

/// Over random 6-DOF poses of a cylinder's core against a box's core at the presets' scale
/// (either body's, separated by up to 3 cm or within 1e-7 m of touching; skewed, parallel
/// and nearly parallel to a face or an edge; the cylinder's side, rim or cap nearest):
/// - wherever [`cylinder_box_pair`] answers, the pair is the closest: the plane across its
///   normal through the box's point bounds the box (its support point along the normal), the
///   plane through the cylinder's point bounds the cylinder, both to 1e-13 m, the points
///   `dist` apart along the normal;
/// - and it is today's pair (GJK and [`exact_pair`]) to 1e-12 m: both points, the distance;
/// - it answers most draws where the side is nearest (counted), and declines the exactly
///   parallel ones (their pair is not unique).
#[test]
fn the_closed_form_cylinder_box_pair_is_the_exact_pair() {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0x21_c7_b0);
    let (mut answered, mut draws, mut parallel_answered) = (0usize, 0usize, 0usize);
    let (mut gjk_intersecting, mut today_inexact) = (0usize, 0usize);
    // today's pair's worst offset where it is the inexact one: cores below and above 1e-7 m apart
    let mut inexact_worst = [0.0f64; 2];
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..20_000 {
        let r = rng.random_range(0.002..0.03);
        let a = rng.random_range(0.01..0.2);
        let h = Vector3::new(
            rng.random_range(0.002..0.06),
            rng.random_range(0.002..0.06),
            rng.random_range(0.002..0.06),
        );
        let u = axis(&mut rng);
        let exactly_parallel = u.iter().any(|x| *x == 0.0);
        // the box at a random pose; the cylinder's axis along `u` in the box's frame
        let box_pose = Isometry3::from_parts(
            Translation3::new(
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
            ),
            UnitQuaternion::from_scaled_axis(unit(&mut rng) * rng.random_range(0.0..3.1)),
        );
        let spin = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), rng.random_range(0.0..6.3));
        let to_u = UnitQuaternion::rotation_between(&Vector3::y(), &u).unwrap_or(
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        // the centre: from a random point near the box, pushed out along a random direction
        // until the cores are apart by a random gap (found by bisection on today's distance)
        let dir = unit(&mut rng);
        let start = Vector3::new(
            rng.random_range(-1.0..1.0) * h.x,
            rng.random_range(-1.0..1.0) * h.y,
            rng.random_range(-1.0..1.0) * h.z,
        );
        let cylinder_piece = piece(
            SharedShape::new(Cylinder::new(a, r)),
            Isometry3::identity(),
            0.002,
        );
        let box_piece = piece(SharedShape::new(Cuboid::new(h)), box_pose, 0.002);
        let at = |s: f64| {
            box_pose * Isometry3::from_parts(Translation3::from(start + dir * s), to_u * spin)
        };
        let dist_at = |s: f64| core_distance(&cylinder_piece, &at(s), &box_piece);
        let gap = if rng.random_bool(0.3) {
            rng.random_range(1e-9..1e-7)
        } else {
            rng.random_range(1e-7..0.03)
        };
        let (mut lo, mut hi) = (0.0, 1.0);
        if dist_at(lo) > gap {
            continue;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if dist_at(mid) > gap {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let cylinder_pose = at(hi);
        draws += 1;
        // either body's: the cylinder the servicer or the target
        let servicer_cylinder = rng.random_bool(0.5);
        let (ps, pose_s, pt) = if servicer_cylinder {
            (cylinder_piece.clone(), cylinder_pose, box_piece.clone())
        } else {
            let moved = piece(SharedShape::new(Cylinder::new(a, r)), cylinder_pose, 0.002);
            (
                piece(
                    SharedShape::new(Cuboid::new(h)),
                    Isometry3::identity(),
                    0.002,
                ),
                box_pose,
                moved,
            )
        };
        let Some(c) = cylinder_box_pair(&ps, &pose_s, &pt) else {
            continue;
        };
        answered += 1;
        parallel_answered += usize::from(exactly_parallel);
        // its own truth: supporting planes across the normal at both points
        let n = c.normal1.into_inner(); // from the servicer toward the target
        assert!((c.normal2.into_inner() + n).norm() <= 1e-15);
        let (on_s, on_t) = (c.point1.coords, c.point2.coords);
        assert!(((on_t - on_s).dot(&n) - c.dist).abs() <= 1e-13, "{c:?}");
        assert!(((on_t - on_s) - n * c.dist).norm() <= 1e-13, "{c:?}");
        let top_s = -lowest(&ps, &pose_s, &-n); // the servicer's highest along n
        let low_t = lowest(&pt, &pt.pose, &n);
        assert!(
            (top_s - on_s.dot(&n)).abs() <= 1e-13,
            "servicer {top_s} vs {}",
            on_s.dot(&n)
        );
        assert!(
            (low_t - on_t.dot(&n)).abs() <= 1e-13,
            "target {low_t} vs {}",
            on_t.dot(&n)
        );
        // today's answer
        let Some(mut today) = core_contact(&ps, &pose_s, &pt, 0, 1.0) else {
            // GJK calls cores this close intersecting
            assert!(c.dist <= 1e-7, "{c:?}");
            gjk_intersecting += 1;
            continue;
        };
        if today.dist <= 0.0 {
            // (or overlapping, by EPA's depth)
            assert!(c.dist <= 1e-7, "{c:?}");
            gjk_intersecting += 1;
            continue;
        }
        exact_pair(&ps, &pose_s, &pt, &mut today);
        // how far each pair's normal is from the cylinder's side normal at its point, rad
        let (cyl_pose, sign) = if servicer_cylinder {
            (pose_s, 1.0)
        } else {
            (pt.pose, -1.0)
        };
        let axis_w = cyl_pose.rotation * Vector3::y();
        let misfit = |k: &Contact| {
            let on_c = if servicer_cylinder {
                k.point1
            } else {
                k.point2
            };
            let radial = on_c.coords - cyl_pose.translation.vector;
            let radial = radial - axis_w * radial.dot(&axis_w);
            let outward = k.normal1.into_inner() * sign;
            (radial.normalize() - outward).norm()
        };
        let (m_closed, m_today) = (misfit(&c), misfit(&today));
        let point_off = (today.point1 - c.point1)
            .norm()
            .max((today.point2 - c.point2).norm());
        let dist_off = (today.dist - c.dist).abs();
        // the closed form's normal is the side's own, to rounding
        assert!(
            m_closed <= 1e-13,
            "closed form's normal {m_closed:e} off the side's"
        );
        // where today's projections stop short (they converge at a rate r/(r + gap): below
        // 1e-7 m apart 1e-10 m to 1e-7 m off, their normal up to 5e-6 off the side's; farther
        // apart up to a few 1e-12 m), the closed form is the exact one: its normal is the
        // side's own and its pair no farther apart
        if point_off > 1e-12 {
            today_inexact += 1;
            let k = usize::from(gap >= 1e-7);
            inexact_worst[k] = inexact_worst[k].max(point_off);
            assert!(m_today >= 10.0 * m_closed, "today {m_today:e}, closed {m_closed:e}, off {point_off:e}, gap {gap:e}, u {u:?}, dist {} {}", c.dist, today.dist);
            assert!(c.dist <= today.dist + 1e-15, "{} > {}", c.dist, today.dist);
            continue;
        }
        worst = (worst.0.max(point_off), worst.1.max(dist_off));
        assert!(
            point_off <= 1e-12 && dist_off <= 1e-12,
            "today's pair {point_off:e} m off, distance {dist_off:e} m (r {r}, a {a}, h {h:?}, \
             u {u:?}, gap {gap}, normals off the side's: closed {m_closed:e}, today {m_today:e})\n{c:?}\n{today:?}"
        );
    }
    eprintln!(
        "{draws} draws, {answered} answered in closed form ({parallel_answered} exactly parallel, \
         {gjk_intersecting} called intersecting by GJK, {today_inexact} where today's pair is \
         the inexact one, off by up to {:.1e} m below 1e-7 m apart, {:.1e} m above); worst \
         against today's pair otherwise: points {:.1e} m, distance {:.1e} m",
        inexact_worst[0], inexact_worst[1], worst.0, worst.1
    );
    assert!(draws >= 10_000, "{draws}");
    assert!(answered * 4 >= draws, "only {answered} of {draws} answered");
    assert!(
        today_inexact * 4 <= answered,
        "{today_inexact} of {answered}"
    );
}
