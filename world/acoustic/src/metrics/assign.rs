//! Minimum-cost assignment (the Hungarian method, O(n²m)), used to pair
//! estimated paths with true targets: the tracker's path ids are
//! arbitrary, so errors are measured under the best pairing.

/// For an n × m cost matrix with n ≤ m, the column assigned to every row,
/// minimising the total cost. Non-finite costs are treated as very large.
pub(crate) fn min_cost_assignment(cost: &[Vec<f64>]) -> Vec<usize> {
    let n = cost.len();
    if n == 0 {
        return Vec::new();
    }
    let m = cost[0].len();
    assert!(n <= m, "assignment needs rows ({n}) ≤ columns ({m})");
    let big = cost
        .iter()
        .flatten()
        .filter(|c| c.is_finite())
        .fold(0.0f64, |a, &c| a.max(c.abs()))
        * 4.0
        + 1.0;
    let c = |i: usize, j: usize| {
        let v = cost[i][j];
        if v.is_finite() {
            v
        } else {
            big
        }
    };
    // Potentials u (rows), v (columns); p[j] = row matched to column j
    // (1-based, 0 = none), the classic e-maxx formulation.
    let mut u = vec![0.0; n + 1];
    let mut v = vec![0.0; m + 1];
    let mut p = vec![0usize; m + 1];
    let mut way = vec![0usize; m + 1];
    for i in 1..=n {
        p[0] = i;
        let mut j0 = 0;
        let mut minv = vec![f64::INFINITY; m + 1];
        let mut used = vec![false; m + 1];
        loop {
            used[j0] = true;
            let i0 = p[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0;
            for j in 1..=m {
                if !used[j] {
                    let cur = c(i0 - 1, j - 1) - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            for j in 0..=m {
                if used[j] {
                    u[p[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if p[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            p[j0] = p[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut out = vec![0; n];
    for j in 1..=m {
        if p[j] > 0 {
            out[p[j] - 1] = j - 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_optimum() {
        let cost = vec![
            vec![4.0, 1.0, 3.0],
            vec![2.0, 0.0, 5.0],
            vec![3.0, 2.0, 2.0],
        ];
        assert_eq!(min_cost_assignment(&cost), vec![1, 0, 2]);
        let rect = vec![
            vec![10.0, 1.0, 10.0, 10.0],
            vec![1.0, 10.0, 10.0, f64::INFINITY],
        ];
        assert_eq!(min_cost_assignment(&rect), vec![1, 0]);
        // Brute force on random 5 × 5.
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as f64 / (1u64 << 31) as f64
        };
        for _ in 0..20 {
            let cost: Vec<Vec<f64>> = (0..5).map(|_| (0..5).map(|_| rnd()).collect()).collect();
            let got = min_cost_assignment(&cost);
            let total = |a: &[usize]| a.iter().enumerate().map(|(i, &j)| cost[i][j]).sum::<f64>();
            let mut best = f64::INFINITY;
            let mut perm = [0, 1, 2, 3, 4];
            permute(&mut perm, 0, &mut |p| best = best.min(total(p)));
            assert!((total(&got) - best).abs() < 1e-12);
        }
    }

    fn permute(a: &mut [usize; 5], k: usize, f: &mut dyn FnMut(&[usize])) {
        if k == a.len() {
            f(a);
            return;
        }
        for i in k..a.len() {
            a.swap(k, i);
            permute(a, k + 1, f);
            a.swap(k, i);
        }
    }
}
