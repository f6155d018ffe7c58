//! Spatial (6D) vector algebra after Featherstone, *Rigid Body Dynamics
//! Algorithms* (2008): motion vectors `[ω; v]` and force vectors `[n; f]`,
//! angular part first, in the coordinates of a link frame whose origin is the
//! link's proximal hinge.
//!
//! Generic over the scalar: `f64` for one state, a SIMD vector of `f64`
//! lanes for [`crate::batch`]'s many states at once.

use nalgebra::{Matrix3, Matrix6, SimdRealField, Vector3, Vector6};

/// The skew-symmetric matrix of `v`: `skew(v) * u = v × u`.
pub fn skew<T: SimdRealField>(v: &Vector3<T>) -> Matrix3<T> {
    let (x, y, z) = (v.x.clone(), v.y.clone(), v.z.clone());
    Matrix3::new(
        T::zero(),
        -z.clone(),
        y.clone(),
        z,
        T::zero(),
        -x.clone(),
        -y,
        x,
        T::zero(),
    )
}

/// Angular part of a spatial vector.
pub fn angular<T: SimdRealField>(m: &Vector6<T>) -> Vector3<T> {
    m.fixed_rows::<3>(0).into_owned()
}

/// Linear part of a spatial vector.
pub fn linear<T: SimdRealField>(m: &Vector6<T>) -> Vector3<T> {
    m.fixed_rows::<3>(3).into_owned()
}

/// A spatial vector from its angular and linear parts.
pub fn spatial<T: SimdRealField>(angular: &Vector3<T>, linear: &Vector3<T>) -> Vector6<T> {
    Vector6::new(
        angular.x.clone(),
        angular.y.clone(),
        angular.z.clone(),
        linear.x.clone(),
        linear.y.clone(),
        linear.z.clone(),
    )
}

/// Motion cross product `v ×m m`.
pub fn cross_motion<T: SimdRealField>(v: &Vector6<T>, m: &Vector6<T>) -> Vector6<T> {
    let (w, v0) = (angular(v), linear(v));
    let (mw, mv) = (angular(m), linear(m));
    spatial(&w.cross(&mw), &(w.cross(&mv) + v0.cross(&mw)))
}

/// Force cross product `v ×* f`.
pub fn cross_force<T: SimdRealField>(v: &Vector6<T>, f: &Vector6<T>) -> Vector6<T> {
    let (w, v0) = (angular(v), linear(v));
    let (n, f0) = (angular(f), linear(f));
    spatial(&(w.cross(&n) + v0.cross(&f0)), &w.cross(&f0))
}

/// A Plücker transform from frame A to frame B: B is rotated by `e` (so a
/// free vector has coordinates `e * u_A` in B) and has its origin at `r`
/// (A coordinates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform<T: SimdRealField = f64> {
    pub e: Matrix3<T>,
    pub r: Vector3<T>,
}

impl<T: SimdRealField + Copy> Transform<T> {
    /// Transforms a motion vector from A to B coordinates.
    pub fn motion(&self, m: &Vector6<T>) -> Vector6<T> {
        let (w, v) = (angular(m), linear(m));
        spatial(&(self.e * w), &(self.e * (v - self.r.cross(&w))))
    }

    /// Transforms a force vector from B back to A coordinates (`Xᵀ f`).
    pub fn force_to_parent(&self, f: &Vector6<T>) -> Vector6<T> {
        let n = self.e.transpose() * angular(f);
        let f0 = self.e.transpose() * linear(f);
        spatial(&(n + self.r.cross(&f0)), &f0)
    }

    /// The 6×6 motion transform matrix.
    pub fn matrix(&self) -> Matrix6<T> {
        let mut x = Matrix6::zeros();
        x.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.e);
        x.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.e);
        x.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&(-self.e * skew(&self.r)));
        x
    }
}

/// The parallel-axis term |c|² I − c cᵀ: a unit mass at `c` adds this to a
/// rotational inertia about the origin.
pub fn parallel_axis(c: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::identity() * c.norm_squared() - c * c.transpose()
}

/// The spatial inertia at the hinge of a body of `mass`, centre of mass `c`
/// and rotational inertia `inertia_com` about the centre of mass.
pub fn rigid_inertia(mass: f64, c: &Vector3<f64>, inertia_com: &Matrix3<f64>) -> Matrix6<f64> {
    let cx = skew(c);
    let mut i = Matrix6::zeros();
    i.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(inertia_com + cx * cx.transpose() * mass));
    i.fixed_view_mut::<3, 3>(0, 3).copy_from(&(cx * mass));
    i.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(cx.transpose() * mass));
    i.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(Matrix3::identity() * mass));
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn transform_matrix_agrees_with_the_fast_paths() {
        let x = Transform {
            e: *Rotation3::from_euler_angles(0.3, -1.1, 2.0).matrix(),
            r: Vector3::new(0.5, -0.2, 1.5),
        };
        let m = Vector6::new(1.0, 2.0, -3.0, 0.5, 0.25, -1.0);
        assert!((x.matrix() * m - x.motion(&m)).norm() < 1e-14);
        assert!((x.matrix().transpose() * m - x.force_to_parent(&m)).norm() < 1e-14);
    }

    #[test]
    fn power_is_invariant_under_transforms() {
        // f_B · v_B = (Xᵀ f_B) · v_A
        let x: Transform = Transform {
            e: *Rotation3::from_euler_angles(-0.7, 0.4, 0.1).matrix(),
            r: Vector3::new(-1.0, 0.3, 0.2),
        };
        let v_a = Vector6::new(0.1, -0.4, 0.9, 2.0, -1.0, 0.5);
        let f_b = Vector6::new(3.0, 1.0, -2.0, 0.7, 0.2, -0.1);
        let p_b = f_b.dot(&x.motion(&v_a));
        assert!((p_b - x.force_to_parent(&f_b).dot(&v_a)).abs() < 1e-13);
    }

    #[test]
    fn rigid_inertia_gives_kinetic_energy_about_the_centre_of_mass() {
        // ½ vᵀ I v equals ½ m |v_c|² + ½ ωᵀ I_c ω.
        let (m, c) = (2.5, Vector3::new(0.3, 0.1, -0.2));
        let ic = Matrix3::new(0.2, 0.01, 0.0, 0.01, 0.3, 0.02, 0.0, 0.02, 0.1);
        let v = Vector6::new(1.0, -2.0, 0.5, 0.3, 0.8, -1.2);
        let (w, v0) = (angular(&v), linear(&v));
        let vc = v0 + w.cross(&c);
        let expected = 0.5 * m * vc.norm_squared() + 0.5 * w.dot(&(ic * w));
        let got = 0.5 * v.dot(&(rigid_inertia(m, &c, &ic) * v));
        assert!((got - expected).abs() < 1e-13);
    }
}
