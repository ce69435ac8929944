//! A plain linear Kalman filter on dynamically sized matrices, written in the textbook
//! form (e.g. Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
//! Navigation*, §5.2; Brown & Hwang, 4th ed., §4.2):
//!
//! ```text
//! predict:  x⁻ = F x,        P⁻ = F P Fᵀ + Q
//! update:   ν = z − H x⁻,    S = H P⁻ Hᵀ + R,    K = P⁻ Hᵀ S⁻¹
//!           x⁺ = x⁻ + K ν,   P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ     (Joseph form)
//! ```
//! It is deliberately naive — whole-matrix products, an explicit `S⁻¹`, heap-allocated
//! `DMatrix` — because its job is to be an obviously correct, independent reference that
//! the optimised filters ([`crate::fusion::ekf11`]) are tested against, not to be fast.

use nalgebra::{DMatrix, DVector};

/// Errors of [`LinearKf`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LinearKfError {
    /// A matrix or vector has the wrong shape.
    #[error("{what} has shape {got:?}, expected {expected:?}")]
    DimensionMismatch {
        what: &'static str,
        expected: (usize, usize),
        got: (usize, usize),
    },
    /// The innovation covariance `S` could not be inverted.
    #[error("the innovation covariance is singular")]
    SingularInnovation,
    /// An input or the result holds NaN or infinity; the filter is unchanged.
    #[error("non-finite value in the input or result; the filter was left unchanged")]
    NonFinite,
}

/// A linear Kalman filter with state `x` and covariance `P`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearKf {
    x: DVector<f64>,
    p: DMatrix<f64>,
}

fn check_shape(
    what: &'static str,
    m: &DMatrix<f64>,
    expected: (usize, usize),
) -> Result<(), LinearKfError> {
    if m.shape() == expected {
        Ok(())
    } else {
        Err(LinearKfError::DimensionMismatch {
            what,
            expected,
            got: m.shape(),
        })
    }
}

fn all_finite<'a>(it: impl IntoIterator<Item = &'a f64>) -> bool {
    it.into_iter().all(|v| v.is_finite())
}

impl LinearKf {
    /// A filter starting at `x0` with covariance `p0`.
    ///
    /// # Errors
    /// [`LinearKfError::DimensionMismatch`] when `p0` is not `n × n` for `n = len(x0)`,
    /// [`LinearKfError::NonFinite`] for NaN or infinite entries.
    pub fn new(x0: DVector<f64>, p0: DMatrix<f64>) -> Result<Self, LinearKfError> {
        let n = x0.len();
        check_shape("P0", &p0, (n, n))?;
        if !(all_finite(x0.iter()) && all_finite(p0.iter())) {
            return Err(LinearKfError::NonFinite);
        }
        Ok(Self { x: x0, p: p0 })
    }

    /// The state dimension.
    pub fn dim(&self) -> usize {
        self.x.len()
    }

    /// The state.
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }

    /// The covariance.
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.p
    }

    /// `x ← F x`, `P ← F P Fᵀ + Q`.
    ///
    /// # Errors
    /// Shape mismatches and non-finite inputs or results; the filter is then unchanged.
    pub fn predict(&mut self, f: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<(), LinearKfError> {
        let n = self.dim();
        check_shape("F", f, (n, n))?;
        check_shape("Q", q, (n, n))?;
        let x = f * &self.x;
        let p = f * &self.p * f.transpose() + q;
        if !(all_finite(x.iter()) && all_finite(p.iter())) {
            return Err(LinearKfError::NonFinite);
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// The measurement update with `z = H x + v`, `v ~ N(0, R)`, in Joseph form.
    /// Returns the normalised innovation squared `νᵀ S⁻¹ ν`.
    ///
    /// # Errors
    /// Shape mismatches, a singular `S`, non-finite inputs or results; the filter is then
    /// unchanged.
    pub fn update(
        &mut self,
        z: &DVector<f64>,
        h: &DMatrix<f64>,
        r: &DMatrix<f64>,
    ) -> Result<f64, LinearKfError> {
        let n = self.dim();
        let m = z.len();
        check_shape("H", h, (m, n))?;
        check_shape("R", r, (m, m))?;
        if !(all_finite(z.iter()) && all_finite(h.iter()) && all_finite(r.iter())) {
            return Err(LinearKfError::NonFinite);
        }
        let nu = z - h * &self.x;
        let s = h * &self.p * h.transpose() + r;
        let s_inv = s.try_inverse().ok_or(LinearKfError::SingularInnovation)?;
        let k = &self.p * h.transpose() * &s_inv;
        let x = &self.x + &k * &nu;
        let a = DMatrix::<f64>::identity(n, n) - &k * h;
        let p = &a * &self.p * a.transpose() + &k * r * k.transpose();
        let nis = (nu.transpose() * &s_inv * &nu)[(0, 0)];
        if !(all_finite(x.iter()) && all_finite(p.iter()) && nis.is_finite()) {
            return Err(LinearKfError::NonFinite);
        }
        self.x = x;
        self.p = p;
        Ok(nis)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn scalar_textbook_case() {
        // Prior N(0, 4), measurement z = 2 with R = 4: posterior mean 1, variance 2.
        let mut kf = LinearKf::new(
            DVector::from_element(1, 0.0),
            DMatrix::from_element(1, 1, 4.0),
        )
        .unwrap();
        let nis = kf
            .update(
                &DVector::from_element(1, 2.0),
                &DMatrix::from_element(1, 1, 1.0),
                &DMatrix::from_element(1, 1, 4.0),
            )
            .unwrap();
        assert_relative_eq!(kf.state()[0], 1.0);
        assert_relative_eq!(kf.covariance()[(0, 0)], 2.0);
        assert_relative_eq!(nis, 0.5);
        // Random walk with Q = 1 over one step.
        kf.predict(
            &DMatrix::from_element(1, 1, 1.0),
            &DMatrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        assert_relative_eq!(kf.covariance()[(0, 0)], 3.0);
    }

    #[test]
    fn shape_errors_and_non_finite_inputs() {
        let mut kf = LinearKf::new(DVector::zeros(2), DMatrix::identity(2, 2)).unwrap();
        let err = kf
            .predict(&DMatrix::identity(3, 3), &DMatrix::identity(2, 2))
            .unwrap_err();
        assert!(matches!(
            err,
            LinearKfError::DimensionMismatch { what: "F", .. }
        ));
        let z = DVector::from_element(1, f64::NAN);
        assert_eq!(
            kf.update(
                &z,
                &DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
                &DMatrix::identity(1, 1)
            ),
            Err(LinearKfError::NonFinite)
        );
        assert_eq!(kf.state(), &DVector::zeros(2));
        assert!(LinearKf::new(DVector::zeros(2), DMatrix::identity(3, 3)).is_err());
    }
}
