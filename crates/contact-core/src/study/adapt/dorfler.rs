//! Dörfler's marking (W. Dörfler, SIAM J. Numer. Anal. 33 (1996) 1106–1124): the smallest set
//! M of cells whose squared indicators hold a share θ of the total,
//!
//! Σ_{T ∈ M} η_T² ≥ θ Σ_T η_T²,
//!
//! taken greedily from the largest indicator down (which gives a set of minimal
//! cardinality). Ties are broken by the lower cell index, so the set depends on the
//! indicators alone.

/// The cells to refine: indices into `squares` (the cells' η_T², here accumulated over a
/// run), in increasing order. θ ∈ (0, 1]; an all-zero `squares` marks nothing.
pub fn mark(squares: &[f64], theta: f64) -> Vec<usize> {
    debug_assert!(theta > 0.0 && theta <= 1.0);
    let total: f64 = squares.iter().sum();
    if total <= 0.0 {
        return Vec::new();
    }
    let mut order: Vec<usize> = (0..squares.len()).collect();
    order.sort_by(|&a, &b| squares[b].total_cmp(&squares[a]).then(a.cmp(&b)));
    let goal = theta * total;
    let mut held = 0.0;
    let mut marked = Vec::new();
    for c in order {
        if held >= goal {
            break;
        }
        held += squares[c];
        marked.push(c);
    }
    marked.sort_unstable();
    marked
}

#[cfg(test)]
mod tests {
    use super::mark;

    #[test]
    fn the_largest_indicators_holding_the_share_are_marked() {
        // Squares 9, 1, 4, 16, 0 of total 30: θ = 0.5 needs 15, reached by 16 alone; θ = 0.8
        // needs 24: 16 + 9 = 25; θ = 1 takes every nonzero one (16 + 9 + 4 + 1 = 30).
        let sq = [9.0, 1.0, 4.0, 16.0, 0.0];
        assert_eq!(mark(&sq, 0.5), vec![3]);
        assert_eq!(mark(&sq, 0.8), vec![0, 3]);
        assert_eq!(mark(&sq, 1.0), vec![0, 1, 2, 3]);
    }

    #[test]
    fn ties_go_to_the_lower_index_and_zero_marks_nothing() {
        assert_eq!(mark(&[1.0, 1.0, 1.0, 1.0], 0.5), vec![0, 1]);
        assert!(mark(&[0.0; 5], 0.5).is_empty());
        assert!(mark(&[], 0.5).is_empty());
    }

    #[test]
    fn the_marked_set_is_minimal() {
        // Any set of fewer cells holds less than the share: the marked set less its smallest
        // member falls short of θ · total.
        let sq: Vec<f64> = (0..50).map(|i| ((i * 37) % 11) as f64 + 0.5).collect();
        let total: f64 = sq.iter().sum();
        for theta in [0.1, 0.3, 0.5, 0.7, 0.9] {
            let m = mark(&sq, theta);
            let held: f64 = m.iter().map(|&c| sq[c]).sum();
            let smallest = m.iter().map(|&c| sq[c]).fold(f64::INFINITY, f64::min);
            assert!(held >= theta * total);
            assert!(held - smallest < theta * total, "θ = {theta}");
        }
    }
}
