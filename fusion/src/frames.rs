//! Frame-typed rotations and vectors, so that a chain of rotations that does not connect does
//! not compile.
//!
//! The crate names a direction-cosine matrix `c_a_b` for the rotation that takes coordinates in
//! frame `b` to coordinates in frame `a` (`v_a = c_a_b · v_b`), and chains them by matching the
//! inner letters: `c_s_i = c_s_b · c_b_e · c_e_i`. [`Rotation<From, To>`] carries the two frames
//! in its type — `c_e_i` is a `Rotation<Icrf, Ecef>` — so the product is only defined when the
//! inner frames agree:
//!
//! - `Rotation<B, C> * Rotation<A, B> = Rotation<A, C>` (`c_c_a = c_c_b · c_b_a`),
//! - `Rotation<A, B> * Vector<A> = Vector<B>` (`v_b = c_b_a · v_a`),
//! - [`Rotation::inverse`] transposes and swaps the frames (`c_a_b = c_b_aᵀ`).
//!
//! The frames are zero-sized marker types and both wrappers are `#[repr(transparent)]` over
//! `nalgebra::Matrix3<f64>` / `Vector3<f64>`: a typed chain performs exactly the nalgebra
//! products written, in the order written, so it is bit-identical to the untyped chain and
//! costs nothing (the design of `sguaba`'s `Rotation<From, To>`, reduced to what the
//! navigation chains need). A frame type names the axes, not an origin: [`Ned`] is the local
//! level at whatever point the rotation was built for.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use std::fmt;
use std::marker::PhantomData;
use std::ops::Mul;

/// A coordinate frame (axes) of the navigation chains; implemented by zero-sized markers.
pub trait Frame {
    /// Short name for debug output.
    const NAME: &'static str;
}

/// Celestial reference frame: GCRS axes (ICRF orientation), the frame of star catalogues and
/// of the star tracker's attitude quaternion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Icrf {}

/// Earth-fixed frame: ITRS (WGS-84 ECEF), x to the Greenwich meridian on the equator, z to
/// the conventional pole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ecef {}

/// Local level: north, east, down (along the ellipsoid normal) at a given point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ned {}

/// Vehicle body, defined by the IMU triad: x forward, y right, z down.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Body {}

/// Star-tracker sensor frame: z the optical axis, x and y across it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StarSensor {}

impl Frame for Icrf {
    const NAME: &'static str = "ICRF";
}
impl Frame for Ecef {
    const NAME: &'static str = "ECEF";
}
impl Frame for Ned {
    const NAME: &'static str = "NED";
}
impl Frame for Body {
    const NAME: &'static str = "body";
}
impl Frame for StarSensor {
    const NAME: &'static str = "star sensor";
}

/// The rotation taking coordinates in frame `From` to coordinates in frame `To`, stored as the
/// direction-cosine matrix `C_to_from` (`v_to = C · v_from`).
#[repr(transparent)]
pub struct Rotation<From: Frame, To: Frame> {
    dcm: Matrix3<f64>,
    frames: PhantomData<fn(From) -> To>,
}

impl<From: Frame, To: Frame> Rotation<From, To> {
    /// Wrap a direction-cosine matrix `C_to_from` (`v_to = dcm · v_from`). The caller asserts
    /// the frames and that `dcm` is a rotation (orthonormal, det +1); nothing is checked, so
    /// that wrapping is free (see `astro_fix::check_rotation` for a check).
    pub fn from_dcm_unchecked(dcm: Matrix3<f64>) -> Self {
        Self {
            dcm,
            frames: PhantomData,
        }
    }

    /// The rotation of a unit quaternion `q_to_from` (Hamilton, `v_to = q v_from q*`).
    pub fn from_quaternion(q: &UnitQuaternion<f64>) -> Self {
        Self::from_dcm_unchecked(q.to_rotation_matrix().into_inner())
    }

    /// The direction-cosine matrix `C_to_from`.
    pub fn dcm(&self) -> &Matrix3<f64> {
        &self.dcm
    }

    /// The direction-cosine matrix `C_to_from`, by value.
    pub fn into_dcm(self) -> Matrix3<f64> {
        self.dcm
    }

    /// The unit quaternion `q_to_from` of this rotation (exact conversion of the matrix as
    /// stored, no re-orthonormalisation).
    pub fn to_quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(self.dcm))
    }

    /// The inverse rotation `C_from_to = C_to_fromᵀ`.
    pub fn inverse(&self) -> Rotation<To, From> {
        Rotation::from_dcm_unchecked(self.dcm.transpose())
    }
}

impl<F: Frame> Rotation<F, F> {
    /// The identity rotation of a frame onto itself.
    pub fn identity() -> Self {
        Self::from_dcm_unchecked(Matrix3::identity())
    }
}

impl<From: Frame, To: Frame> Clone for Rotation<From, To> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<From: Frame, To: Frame> Copy for Rotation<From, To> {}

impl<From: Frame, To: Frame> PartialEq for Rotation<From, To> {
    fn eq(&self, other: &Self) -> bool {
        self.dcm == other.dcm
    }
}

impl<From: Frame, To: Frame> fmt::Debug for Rotation<From, To> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Rotation<{} → {}>{:?}", From::NAME, To::NAME, self.dcm)
    }
}

impl<A: Frame, B: Frame, C: Frame> Mul<Rotation<A, B>> for Rotation<B, C> {
    type Output = Rotation<A, C>;
    /// `c_c_a = c_c_b · c_b_a`.
    fn mul(self, rhs: Rotation<A, B>) -> Rotation<A, C> {
        Rotation::from_dcm_unchecked(self.dcm * rhs.dcm)
    }
}

impl<A: Frame, B: Frame, C: Frame> Mul<&Rotation<A, B>> for &Rotation<B, C> {
    type Output = Rotation<A, C>;
    /// `c_c_a = c_c_b · c_b_a`.
    fn mul(self, rhs: &Rotation<A, B>) -> Rotation<A, C> {
        Rotation::from_dcm_unchecked(self.dcm * rhs.dcm)
    }
}

impl<A: Frame, B: Frame> Mul<Vector<A>> for Rotation<A, B> {
    type Output = Vector<B>;
    /// `v_b = c_b_a · v_a`.
    fn mul(self, rhs: Vector<A>) -> Vector<B> {
        Vector::new(self.dcm * rhs.v)
    }
}

impl<A: Frame, B: Frame> Mul<&Vector<A>> for &Rotation<A, B> {
    type Output = Vector<B>;
    /// `v_b = c_b_a · v_a`.
    fn mul(self, rhs: &Vector<A>) -> Vector<B> {
        Vector::new(self.dcm * rhs.v)
    }
}

/// A 3-vector resolved in the axes of frame `F` (a direction, velocity, … — the unit is the
/// caller's).
#[repr(transparent)]
pub struct Vector<F: Frame> {
    v: Vector3<f64>,
    frame: PhantomData<fn() -> F>,
}

impl<F: Frame> Vector<F> {
    /// Wrap coordinates resolved in `F`.
    pub fn new(v: Vector3<f64>) -> Self {
        Self {
            v,
            frame: PhantomData,
        }
    }

    /// The coordinates in `F`.
    pub fn coords(&self) -> &Vector3<f64> {
        &self.v
    }

    /// The coordinates in `F`, by value.
    pub fn into_coords(self) -> Vector3<f64> {
        self.v
    }
}

impl<F: Frame> Clone for Vector<F> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<F: Frame> Copy for Vector<F> {}

impl<F: Frame> PartialEq for Vector<F> {
    fn eq(&self, other: &Self) -> bool {
        self.v == other.v
    }
}

impl<F: Frame> fmt::Debug for Vector<F> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Vector<{}>{:?}", F::NAME, self.v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::c_n_b_from_rpy;
    use crate::celestial::{EarthOrientation, c_e_i, icrf_to_ecef};
    use crate::earth::{c_e_n, ned_to_ecef};
    use crate::time::GpsTime;
    use proptest::prelude::*;

    /// Zero cost: the wrappers are exactly their nalgebra payloads.
    #[test]
    fn wrappers_have_the_layout_of_their_payload() {
        assert_eq!(
            std::mem::size_of::<Rotation<Icrf, Ecef>>(),
            std::mem::size_of::<Matrix3<f64>>()
        );
        assert_eq!(
            std::mem::size_of::<Vector<Body>>(),
            std::mem::size_of::<Vector3<f64>>()
        );
    }

    fn rotation<A: Frame, B: Frame>(axis: [f64; 3], angle: f64) -> Rotation<A, B> {
        let axis = Vector3::from(axis);
        let q = if axis.norm() > 1e-6 {
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle)
        } else {
            UnitQuaternion::identity()
        };
        Rotation::from_quaternion(&q)
    }

    fn axis() -> impl Strategy<Value = [f64; 3]> {
        prop::array::uniform3(-1.0..1.0_f64)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]

        /// The star-tracker chain `c_s_i = c_s_b · c_b_n · c_n_e · c_e_i` built from the typed
        /// constructors equals the untyped matrix chain bit for bit, and applying it to a
        /// vector equals the matrix–vector product.
        #[test]
        fn typed_chain_equals_untyped_chain(
            lat in -1.5..1.5_f64, lon in -3.1..3.1_f64,
            roll in -3.1..3.1_f64, pitch in -1.5..1.5_f64, heading in -3.1..3.1_f64,
            mount_axis in axis(), mount_angle in -3.1..3.1_f64,
            days in 0.0..20_000.0_f64,
            v in prop::array::uniform3(-10.0..10.0_f64),
        ) {
            let t = GpsTime { ns: (days * 86_400e9) as i64 };
            let eop = EarthOrientation::default();
            let c_s_b: Rotation<Body, StarSensor> = rotation(mount_axis, mount_angle);
            let c_n_b = crate::attitude::body_to_ned(roll, pitch, heading);
            let c_e_n_t = ned_to_ecef(lat, lon);
            let c_e_i_t = icrf_to_ecef(t, &eop);
            let typed = c_s_b * c_n_b.inverse() * c_e_n_t.inverse() * c_e_i_t;
            let untyped = c_s_b.dcm()
                * c_n_b_from_rpy(roll, pitch, heading).transpose()
                * c_e_n(lat, lon).transpose()
                * c_e_i(t, &eop);
            prop_assert_eq!(typed.dcm(), &untyped);
            let v_i = Vector::<Icrf>::new(Vector3::from(v));
            prop_assert_eq!((typed * v_i).into_coords(), untyped * Vector3::from(v));
        }

        /// `inverse ∘ rotation` is the identity in both orders, the inverse of the inverse is
        /// the rotation exactly, and a quaternion round trip reproduces the matrix. Each entry
        /// of `C` carries a few ulps of rounding (from the quaternion or the sines), a 3-term
        /// dot product adds three more: `TOL` = 16 ε bounds `|Cᵀ C − I|` with headroom.
        #[test]
        fn inverse_composed_with_rotation_is_identity(
            a in axis(), angle in -3.1..3.1_f64,
            lat in -1.5..1.5_f64, lon in -3.1..3.1_f64,
        ) {
            const TOL: f64 = 16.0 * f64::EPSILON;
            let r: Rotation<Body, StarSensor> = rotation(a, angle);
            let i1 = r.inverse() * r;
            let i2 = r * r.inverse();
            prop_assert!((i1.dcm() - Rotation::<Body, Body>::identity().dcm()).abs().max() < TOL);
            prop_assert!((i2.dcm() - Matrix3::identity()).abs().max() < TOL);
            prop_assert_eq!(r.inverse().inverse(), r);
            let q = Rotation::<Body, StarSensor>::from_quaternion(&r.to_quaternion());
            prop_assert!((q.dcm() - r.dcm()).abs().max() < TOL);
            let n = ned_to_ecef(lat, lon);
            prop_assert!(((n.inverse() * n).dcm() - Matrix3::identity()).abs().max() < TOL);
        }
    }
}
