//! The relaxation kernel r(s) of R(s) = r(s)·I, which weighs the memory sum of (3.1):
//! a Prony series, an expression of s or a table. The scene reads it, `history` sums with
//! it, `kernel_fit` compresses it and `resources` prices its memory.

use crate::expr::{Expr, Point};

/// The relaxation function r(s) of R(s) = r(s)·I.
#[derive(Debug)]
pub enum Kernel {
    /// Σ a_i exp(−b_i s): pairs (a_i, b_i); memory by the exact O(1) recursion.
    Prony(Vec<(f64, f64)>),
    /// An expression of s; memory by the direct O(n) sum.
    Expr(Box<Expr>),
    /// Piecewise linear through (s_i, r_i), constant beyond the ends; direct sum.
    Table(Vec<f64>, Vec<f64>),
}

impl Kernel {
    /// r(s).
    pub fn eval(&self, s: f64) -> f64 {
        match self {
            Kernel::Prony(terms) => terms.iter().map(|(a, b)| a * (-b * s).exp()).sum(),
            Kernel::Expr(e) => e.eval(&Point {
                s,
                ..Default::default()
            }),
            Kernel::Table(ss, rs) => {
                let i = ss.partition_point(|&x| x <= s);
                if i == 0 {
                    rs[0]
                } else if i == ss.len() {
                    rs[rs.len() - 1]
                } else {
                    let w = (s - ss[i - 1]) / (ss[i] - ss[i - 1]);
                    rs[i - 1] + w * (rs[i] - rs[i - 1])
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_kernel_interpolates() {
        let k = Kernel::Table(vec![0.0, 1.0], vec![1.0, 0.0]);
        assert_eq!(k.eval(0.25), 0.75);
        assert_eq!(k.eval(2.0), 0.0);
        assert_eq!(k.eval(-1.0), 1.0);
    }
}
