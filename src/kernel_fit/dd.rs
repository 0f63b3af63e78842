//! Double-double numbers: an unevaluated sum hi + lo of two f64 with |lo| ≤ ulp(hi)/2, about
//! 32 significant digits (Dekker 1971; the algorithms of Hida, Li and Bailey's QD library,
//! "accurate" addition). Only what the non-negative least squares of the fit needs: the four
//! operations, the square root and the comparison (lexicographic on (hi, lo), which orders
//! normalized pairs by value).

use std::ops::{Add, Div, Mul, Neg, Sub};

#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
pub(super) struct Dd {
    hi: f64,
    lo: f64,
}

impl Dd {
    pub(super) const ZERO: Dd = Dd { hi: 0.0, lo: 0.0 };

    /// The nearest f64.
    pub(super) fn to_f64(self) -> f64 {
        self.hi + self.lo
    }

    /// √x by one Newton step from the f64 root (0 for x ≤ 0).
    pub(super) fn sqrt(self) -> Dd {
        if self.hi <= 0.0 {
            return Dd::ZERO;
        }
        let root = Dd::from(self.hi.sqrt());
        root + Dd::from((self - root * root).hi / (2.0 * root.hi))
    }
}

impl From<f64> for Dd {
    fn from(x: f64) -> Dd {
        Dd { hi: x, lo: 0.0 }
    }
}

/// a + b = s + e exactly (Knuth's TwoSum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let v = s - a;
    (s, (a - (s - v)) + (b - v))
}

/// a + b = s + e exactly where |a| ≥ |b| (Dekker's FastTwoSum): the normalized pair.
fn renormalized(a: f64, b: f64) -> Dd {
    let s = a + b;
    Dd {
        hi: s,
        lo: b - (s - a),
    }
}

fn sum(x: Dd, y: Dd) -> Dd {
    let (s, e) = two_sum(x.hi, y.hi);
    let (t, f) = two_sum(x.lo, y.lo);
    let head = renormalized(s, e + t);
    renormalized(head.hi, head.lo + f)
}

fn product(x: Dd, y: Dd) -> Dd {
    let p = x.hi * y.hi;
    // TwoProduct by a fused multiply-add: x.hi·y.hi = p + e exactly.
    let e = x.hi.mul_add(y.hi, -p);
    renormalized(p, e + (x.hi * y.lo + x.lo * y.hi))
}

/// x / y by three correction steps of the f64 quotient.
fn quotient(x: Dd, y: Dd) -> Dd {
    let q1 = x.hi / y.hi;
    let r = x - y * Dd::from(q1);
    let q2 = r.hi / y.hi;
    let r = r - y * Dd::from(q2);
    let q3 = r.hi / y.hi;
    renormalized(q1, q2) + Dd::from(q3)
}

impl Add for Dd {
    type Output = Dd;
    fn add(self, y: Dd) -> Dd {
        sum(self, y)
    }
}

impl Neg for Dd {
    type Output = Dd;
    fn neg(self) -> Dd {
        Dd {
            hi: -self.hi,
            lo: -self.lo,
        }
    }
}

impl Sub for Dd {
    type Output = Dd;
    fn sub(self, y: Dd) -> Dd {
        sum(self, -y)
    }
}

impl Mul for Dd {
    type Output = Dd;
    fn mul(self, y: Dd) -> Dd {
        product(self, y)
    }
}

impl Div for Dd {
    type Output = Dd;
    fn div(self, y: Dd) -> Dd {
        quotient(self, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn carries_what_f64_rounds_away() {
        let third = Dd::from(1.0) / Dd::from(3.0);
        // 1/3 · 3 − 1 is 0 to ~1e-32, where f64 leaves 1/3's rounding error.
        assert!((third * Dd::from(3.0) - Dd::from(1.0)).to_f64().abs() < 1e-31);
        let tiny = Dd::from(1.0) + Dd::from(1e-20);
        assert_eq!((tiny - Dd::from(1.0)).to_f64(), 1e-20);
        let two = Dd::from(2.0).sqrt();
        assert!((two * two - Dd::from(2.0)).to_f64().abs() < 1e-31);
        assert!(Dd::from(1.0) < tiny && -tiny < Dd::ZERO);
    }
}
