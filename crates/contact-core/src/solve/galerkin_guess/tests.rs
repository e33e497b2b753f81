use super::*;
use crate::linalg::cholesky::tests::laplace_1d;
use crate::linalg::Csr;

const N: usize = 40;

/// K: a shifted 1D Laplacian on N free DOFs, the last `m` of them tangential.
fn operator() -> Csr {
    let mut k = laplace_1d(N);
    for i in 0..N {
        let d = k.indptr[i]..k.indptr[i + 1];
        for (j, v) in k.indices[d.clone()].iter().zip(&mut k.values[d]) {
            if *j as usize == i {
                *v += 0.1;
            }
        }
    }
    k
}

fn pseudo_random(seed: usize) -> Vec<f64> {
    (0..N)
        .map(|i| ((i * 7919 + seed * 104_729) as f64 * 0.618_033_988_75).fract() - 0.5)
        .collect()
}

/// E(w) = ½ wᵀKw − fᵀw + Σ_i ω_i j(|x_i|).
fn energy(k: &Csr, f: &[f64], w: &[f64], contact: &Contact) -> f64 {
    let mut kw = vec![0.0; N];
    k.mul_vec(w, &mut kw);
    let quadratic: f64 = w
        .iter()
        .zip(&kw)
        .zip(f)
        .map(|((w, k), f)| 0.5 * w * k - f * w)
        .sum();
    let friction: f64 = contact
        .weights
        .iter()
        .enumerate()
        .map(|(i, om)| {
            let x = &w[contact.n_interior + contact.block * i..][..contact.block];
            om * contact
                .law
                .potential(x.iter().map(|v| v * v).sum::<f64>().sqrt())
        })
        .sum();
    quadratic + friction
}

/// Puts the vectors into a space in order (each as a "solution" after a projection).
fn space_of(k: &Csr, vectors: &[Vec<f64>]) -> SolutionSpace {
    let mut space = SolutionSpace::new(N, 12);
    let mut scratch = vec![0.0; N];
    for v in vectors {
        space.project(&vec![0.0; N], &mut scratch);
        space.extend(k, v);
    }
    space
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// A minimiser w* with slipping and sticking nodes, and its load: f = K w* + s, s_C a
/// subgradient of the friction term (μ ẑ at a slip node, inside the ball at a stick node).
fn manufactured(contact: &Contact, stick: &[usize]) -> (Vec<f64>, Vec<f64>) {
    let k = operator();
    let mut w = pseudo_random(1);
    let mut s = vec![0.0; N];
    for (i, &om) in contact.weights.iter().enumerate() {
        let c = contact.n_interior + contact.block * i;
        let x = &mut w[c..c + contact.block];
        if stick.contains(&i) {
            x.iter_mut().for_each(|v| *v = 0.0);
            s[c] = 0.5 * om * contact.law.mu(0.0);
            continue;
        }
        let rho = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        for r in 0..contact.block {
            s[c + r] = om * contact.law.mu(rho) * x[r] / rho;
        }
    }
    let mut f = vec![0.0; N];
    k.mul_vec(&w, &mut f);
    f.iter_mut().zip(&s).for_each(|(f, s)| *f += s);
    (w, f)
}

/// Other vectors of the span: w* perturbed in the interior and at the slip nodes only.
fn perturbations(w: &[f64], contact: &Contact, stick: &[usize], count: usize) -> Vec<Vec<f64>> {
    (0..count)
        .map(|j| {
            let mut v: Vec<f64> = w
                .iter()
                .zip(pseudo_random(10 + j))
                .map(|(w, r)| w + 0.3 * r)
                .collect();
            for &i in stick {
                let c = contact.n_interior + contact.block * i;
                v[c..c + contact.block].iter_mut().for_each(|x| *x = 0.0);
            }
            v
        })
        .collect()
}

#[test]
fn a_minimiser_in_the_span_is_found_in_2d_and_3d() {
    let law = FrictionLaw::Tresca { g: 1.5 };
    for block in [1, 2] {
        let weights = [0.4, 0.7, 0.2, 0.5];
        let contact = Contact {
            n_interior: N - block * weights.len(),
            block,
            weights: &weights,
            law: &law,
        };
        let stick = [1];
        let (w_star, f) = manufactured(&contact, &stick);
        let k = operator();
        let mut vectors = perturbations(&w_star, &contact, &stick, 3);
        vectors.insert(1, w_star.clone());
        let mut space = space_of(&k, &vectors);
        let mut w = vec![0.0; N];
        let its = minimise(&mut space, &f, &contact, &mut w).expect("a space");
        let err: Vec<f64> = w.iter().zip(&w_star).map(|(a, b)| a - b).collect();
        assert!(
            max_abs(&err) < 1e-10 * max_abs(&w_star),
            "block {block}: error {:e} after {its} iterations",
            max_abs(&err)
        );
        assert!(its >= 1, "the newest vector is not the minimiser");
    }
}

#[test]
fn a_span_with_every_node_at_rest_gives_the_k_projection() {
    let law = FrictionLaw::Tresca { g: 1.0 };
    let weights = [0.3; 6];
    let contact = Contact {
        n_interior: N - 6,
        block: 1,
        weights: &weights,
        law: &law,
    };
    let k = operator();
    let vectors: Vec<Vec<f64>> = (0..4)
        .map(|j| {
            let mut v = pseudo_random(20 + j);
            v[N - 6..].iter_mut().for_each(|x| *x = 0.0);
            v
        })
        .collect();
    let f = pseudo_random(99);
    let mut space = space_of(&k, &vectors);
    let mut guess = vec![0.0; N];
    minimise(&mut space, &f, &contact, &mut guess).unwrap();
    let mut projection = vec![0.0; N];
    space.project(&f, &mut projection);
    let err: Vec<f64> = guess.iter().zip(&projection).map(|(a, b)| a - b).collect();
    assert!(
        max_abs(&err) < 1e-12 * max_abs(&projection),
        "{:e}",
        max_abs(&err)
    );
}

#[test]
fn the_guess_never_has_more_energy_than_the_newest_velocity() {
    // Every node moves in some vector (Ê is non-smooth at the minimiser), a slip-weakening
    // law with small weights (E stays convex), 2D and 3D, several loads.
    let law = FrictionLaw::SlipWeakening {
        mu0: 2.0,
        mu1: 0.5,
        alpha: 3.0,
    };
    for block in [1, 2] {
        let weights = [0.05, 0.02, 0.04];
        let contact = Contact {
            n_interior: N - block * weights.len(),
            block,
            weights: &weights,
            law: &law,
        };
        let k = operator();
        for seed in 0..5 {
            let vectors: Vec<Vec<f64>> = (0..5).map(|j| pseudo_random(30 + 7 * seed + j)).collect();
            let newest = vectors.last().unwrap().clone();
            let f: Vec<f64> = pseudo_random(70 + seed).iter().map(|v| 0.2 * v).collect();
            let mut space = space_of(&k, &vectors);
            let mut w = vec![0.0; N];
            minimise(&mut space, &f, &contact, &mut w).unwrap();
            let (e_guess, e_newest) = (
                energy(&k, &f, &w, &contact),
                energy(&k, &f, &newest, &contact),
            );
            assert!(
                e_guess <= e_newest + 1e-12 * e_newest.abs(),
                "block {block}, seed {seed}: {e_guess} > {e_newest}"
            );
        }
    }
}

#[test]
fn an_empty_space_leaves_the_start_alone() {
    let law = FrictionLaw::Tresca { g: 1.0 };
    let contact = Contact {
        n_interior: N - 2,
        block: 1,
        weights: &[0.1, 0.1],
        law: &law,
    };
    let mut space = SolutionSpace::new(N, 12);
    let mut w = vec![3.0; N];
    assert_eq!(minimise(&mut space, &vec![1.0; N], &contact, &mut w), None);
    assert!(w.iter().all(|&v| v == 3.0));
}
