//! Assembling a loop's LTI model from its blocks: interconnection of parts at one
//! rate, and exact lifting of a faster part to a slower rate.
//!
//! A *part* is a discrete state-space model x⁺ = A x + B u, y = C x + D u whose
//! inputs and outputs are named by graph ports. [`compose`] closes the
//! connections between parts (u = M y + v, v an injected signal at every input):
//!
//! y = E C x + E D v,  E = (I − D M)⁻¹,
//! x⁺ = (A + B M E C) x + (B + B M E D) v.
//!
//! [`lift`] turns a part that runs at period p, whose inputs are held over the
//! slower period m·p (they come from slower blocks through zero-order holds), into
//! the exact model at period m·p, sampled at the instants the slower blocks run:
//! A_m = A^m, B_m = Σ_{k<m} A^k B, C and D unchanged.

use nalgebra::DMatrix;

/// A port of a block: (execution index of the block, port index).
pub(crate) type PortRef = (usize, usize);

/// A connection: from an output port to an input port.
pub(crate) type Edge = (PortRef, PortRef);

/// A discrete model whose inputs and outputs are graph ports.
#[derive(Debug, Clone)]
pub(crate) struct Part {
    pub a: DMatrix<f64>,
    pub b: DMatrix<f64>,
    pub c: DMatrix<f64>,
    pub d: DMatrix<f64>,
    /// Input ports with their widths, in the order of the columns of B and D.
    pub inputs: Vec<(PortRef, usize)>,
    /// Output ports with their widths, in the order of the rows of C and D.
    pub outputs: Vec<(PortRef, usize)>,
}

impl Part {
    /// Offset of port `p` among `list` (inputs or outputs), with its width.
    fn offset(list: &[(PortRef, usize)], p: PortRef) -> Option<(usize, usize)> {
        let mut off = 0;
        for &(q, w) in list {
            if q == p {
                return Some((off, w));
            }
            off += w;
        }
        None
    }
    /// Offset and width of input port `p`.
    pub fn input_offset(&self, p: PortRef) -> Option<(usize, usize)> {
        Self::offset(&self.inputs, p)
    }
    /// Offset and width of output port `p`.
    pub fn output_offset(&self, p: PortRef) -> Option<(usize, usize)> {
        Self::offset(&self.outputs, p)
    }
}

/// Block-diagonal stack of `parts`, then close every edge of `edges` whose two
/// ends are among the parts, except `open`.
pub(crate) fn compose(parts: &[Part], edges: &[Edge], open: Option<Edge>) -> Result<Part, String> {
    let n: usize = parts.iter().map(|p| p.a.nrows()).sum();
    let m: usize = parts.iter().map(|p| p.b.ncols()).sum();
    let p: usize = parts.iter().map(|p| p.c.nrows()).sum();
    let mut a = DMatrix::zeros(n, n);
    let mut b = DMatrix::zeros(n, m);
    let mut c = DMatrix::zeros(p, n);
    let mut d = DMatrix::zeros(p, m);
    let (mut xo, mut uo, mut yo) = (0, 0, 0);
    let mut inputs = Vec::new();
    let mut outputs = Vec::new();
    for part in parts {
        let (nx, nu, ny) = (part.a.nrows(), part.b.ncols(), part.c.nrows());
        a.view_mut((xo, xo), (nx, nx)).copy_from(&part.a);
        b.view_mut((xo, uo), (nx, nu)).copy_from(&part.b);
        c.view_mut((yo, xo), (ny, nx)).copy_from(&part.c);
        d.view_mut((yo, uo), (ny, nu)).copy_from(&part.d);
        xo += nx;
        uo += nu;
        yo += ny;
        inputs.extend_from_slice(&part.inputs);
        outputs.extend_from_slice(&part.outputs);
    }
    let stacked = Part {
        a,
        b,
        c,
        d,
        inputs,
        outputs,
    };
    // u = M y + v.
    let mut mm = DMatrix::zeros(m, p);
    let mut any = false;
    for &(from, to) in edges {
        if Some((from, to)) == open {
            continue;
        }
        if let (Some((yo, w)), Some((uo, wi))) =
            (stacked.output_offset(from), stacked.input_offset(to))
        {
            if w != wi {
                return Err(format!("connection of widths {w} and {wi}"));
            }
            for j in 0..w {
                mm[(uo + j, yo + j)] = 1.0;
            }
            any = true;
        }
    }
    if !any {
        return Ok(stacked);
    }
    let i_dm = DMatrix::identity(p, p) - &stacked.d * &mm;
    let e = i_dm.lu().try_inverse().ok_or_else(|| {
        "the loop is algebraic at this rate (I − D·M is singular: a feed-through loop with gain 1)"
            .to_string()
    })?;
    let ec = &e * &stacked.c;
    let ed = &e * &stacked.d;
    let bm = &stacked.b * &mm;
    Ok(Part {
        a: &stacked.a + &bm * &ec,
        b: &stacked.b + &bm * &ed,
        c: ec,
        d: ed,
        inputs: stacked.inputs,
        outputs: stacked.outputs,
    })
}

/// The exact model at period m·p of a part running at period p whose inputs are
/// held over m·p: A^m, Σ_{k<m} A^k B, C, D.
pub(crate) fn lift(part: &Part, m: u64) -> Part {
    let n = part.a.nrows();
    let mut ak = DMatrix::identity(n, n);
    let mut bsum = DMatrix::zeros(n, part.b.ncols());
    for _ in 0..m {
        bsum += &ak * &part.b;
        ak = &part.a * &ak;
    }
    Part {
        a: ak,
        b: bsum,
        c: part.c.clone(),
        d: part.d.clone(),
        inputs: part.inputs.clone(),
        outputs: part.outputs.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scalar(a: f64, b: f64, c: f64, d: f64, i: PortRef, o: PortRef) -> Part {
        Part {
            a: DMatrix::from_element(1, 1, a),
            b: DMatrix::from_element(1, 1, b),
            c: DMatrix::from_element(1, 1, c),
            d: DMatrix::from_element(1, 1, d),
            inputs: vec![(i, 1)],
            outputs: vec![(o, 1)],
        }
    }

    #[test]
    fn unity_feedback_of_an_integrator_has_the_textbook_pole() {
        // G(z) = k T/(z − 1) in a loop with a gain −1 (a negative sum): the closed
        // loop pole is 1 − kT.
        let kt = 0.3;
        let g = scalar(1.0, 1.0, kt, 0.0, (0, 0), (0, 0));
        let neg = Part {
            a: DMatrix::zeros(0, 0),
            b: DMatrix::zeros(0, 1),
            c: DMatrix::zeros(1, 0),
            d: DMatrix::from_element(1, 1, -1.0),
            inputs: vec![((1, 0), 1)],
            outputs: vec![((1, 0), 1)],
        };
        let edges = [((0, 0), (1, 0)), ((1, 0), (0, 0))];
        let cl = compose(&[g, neg], &edges, None).unwrap();
        assert!((cl.a[(0, 0)] - (1.0 - kt)).abs() < 1e-15);
    }

    #[test]
    fn lifting_matches_stepping_the_fast_model() {
        let part = scalar(0.9, 0.5, 2.0, 0.1, (0, 0), (0, 0));
        let m = 7;
        let l = lift(&part, m);
        // Step the fast model m times with a held input from x = 1.
        let (mut x, u) = (1.0, 0.4);
        for _ in 0..m {
            x = 0.9 * x + 0.5 * u;
        }
        let lx = l.a[(0, 0)] * 1.0 + l.b[(0, 0)] * u;
        assert!((lx - x).abs() < 1e-14);
    }
}
