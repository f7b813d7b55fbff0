//! Gradient and forward checks of the hand-written network against two independent oracles:
//! - candle (autodiff): the same network built from the same weights, scalar loss `sum(w ⊙ Q)`, with the
//!   Bootstrapped 1/K trunk scaling built as `h/K + detach(h)(1 - 1/K)` (same value, 1/K gradient);
//! - central finite differences of an f64 re-implementation of the forward pass (true gradients; for
//!   Bootstrap the trunk's analytic gradient times K must match them).

use candle_core::{Device, Tensor, Var};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::ops::Range;

use super::*;

const OBS_DIM: usize = 3;
const N_ACTIONS: usize = 2;
const BATCH: usize = 5;

struct Case {
    net: QNet,
    x: Vec<f32>,
    /// Loss weights in forward's output layout [head][batch][action]: `L = sum(w ⊙ Q)`, so `dL/dQ = w`.
    w: Vec<f32>,
    noise: Option<NoiseSample>,
}

fn case(kind: OutputKind, seed: u64, with_noise: bool) -> Case {
    case_with(kind, seed, with_noise, &[HIDDEN, HIDDEN])
}

/// Depths 1 to 4 with uneven widths other than the paper's, for the checks of configurable hidden layers.
const OTHER_WIDTHS: [&[usize]; 4] = [&[7], &[7, 13], &[9, 5, 11], &[5, 7, 3, 9]];

fn case_with(kind: OutputKind, seed: u64, with_noise: bool, hidden: &[usize]) -> Case {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut net = QNet::with_hidden(OBS_DIM, N_ACTIONS, kind, hidden, &mut rng);
    // Spread sigma so every sigma entry gets a distinct value (the initial value is a constant).
    if let OutputKind::Noisy = kind {
        let layout = *net.layout();
        for p in &mut net.parameters_mut()
            [layout.sigma_w.start..layout.sigma_b.start + layout.sigma_b.len]
        {
            *p *= rng.random_range(0.5f32..1.5);
        }
    }
    let x = (0..BATCH * OBS_DIM)
        .map(|_| rng.random_range(-2.0f32..2.0))
        .collect();
    let w = (0..kind.heads() * BATCH * N_ACTIONS)
        .map(|_| rng.random_range(-1.0f32..1.0))
        .collect();
    let noise = with_noise.then(|| {
        let mut sample = NoiseSample::with_inputs(net.features_len(), N_ACTIONS);
        sample.resample(&mut rng);
        sample
    });
    Case { net, x, w, noise }
}

fn analytic(case: &Case) -> (Vec<f32>, Grads) {
    let mut ws = Workspace::new(&case.net, BATCH + 3);
    let q = case
        .net
        .forward(&case.x, BATCH, case.noise.as_ref(), &mut ws)
        .to_vec();
    let mut grads = Grads::new(&case.net);
    // Garbage in the gradient buffer must be overwritten, not accumulated.
    grads.data.fill(123.0);
    case.net.backward(&mut ws, &case.w, &mut grads);
    (q, grads)
}

/// A layout's observation size, action count, output width and head count.
fn sizes(layout: &Layout) -> (usize, usize, usize, usize) {
    (
        layout.obs_dim,
        layout.n_actions,
        layout.out_width,
        layout.heads(),
    )
}

/// Independent f64 forward pass on the flat parameters, following the layout documented on `Layout`
/// with explicit index arithmetic. Returns Q in [head][batch][action] order.
fn reference_q(layout: &Layout, p: &[f64], x: &[f64], noise: Option<&NoiseSample>) -> Vec<f64> {
    let (d, a, width, heads) = sizes(layout);
    let n2 = *layout.hidden.last().unwrap();
    let batch = x.len() / d;
    let mut q = vec![0.0; heads * batch * a];
    for b in 0..batch {
        // The trunk, layer by layer: weights `[in][out]` from `fc_w[layer].start`.
        let mut h2 = x[b * d..(b + 1) * d].to_vec();
        for (layer, &n) in layout.hidden.iter().enumerate() {
            let input = std::mem::take(&mut h2);
            h2 = (0..n)
                .map(|o| {
                    let mut s = p[layout.fc_b[layer].start + o];
                    for (i, &v) in input.iter().enumerate() {
                        s += v * p[layout.fc_w[layer].start + i * n + o];
                    }
                    s.max(0.0)
                })
                .collect();
        }
        match layout.kind {
            OutputKind::Plain | OutputKind::Bootstrap { .. } => {
                for k in 0..heads {
                    for act in 0..a {
                        let col = k * a + act;
                        let mut s = p[layout.out_b.start + col];
                        for (i, &h2_i) in h2.iter().enumerate() {
                            s += h2_i * p[layout.out_w.start + i * width + col];
                        }
                        q[(k * batch + b) * a + act] = s;
                    }
                }
            }
            OutputKind::Noisy => {
                for act in 0..a {
                    let (eps_out, eps_in): (f64, Vec<f64>) = match noise {
                        Some(n) => (
                            n.output_factors()[act] as f64,
                            n.input_factors().iter().map(|&e| e as f64).collect(),
                        ),
                        None => (0.0, vec![0.0; n2]),
                    };
                    let mut s =
                        p[layout.out_b.start + act] + p[layout.sigma_b.start + act] * eps_out;
                    for i in 0..n2 {
                        let weight = p[layout.out_w.start + act * n2 + i]
                            + p[layout.sigma_w.start + act * n2 + i] * eps_out * eps_in[i];
                        s += weight * h2[i];
                    }
                    q[b * a + act] = s;
                }
            }
        }
    }
    q
}

fn reference_loss(case: &Case, p: &[f64]) -> f64 {
    let x: Vec<f64> = case.x.iter().map(|&v| v as f64).collect();
    let q = reference_q(case.net.layout(), p, &x, case.noise.as_ref());
    q.iter().zip(&case.w).map(|(q, &w)| q * w as f64).sum()
}

/// `(segment, name, is_trunk)` for every tensor of the layout.
fn segments(layout: &Layout) -> Vec<(Segment, String, bool)> {
    let mut all = Vec::new();
    for layer in 0..layout.hidden.len() {
        all.push((layout.fc_w[layer], format!("fc{}_w", layer + 1), true));
        all.push((layout.fc_b[layer], format!("fc{}_b", layer + 1), true));
    }
    for (segment, name) in [
        (layout.out_w, "out_w"),
        (layout.out_b, "out_b"),
        (layout.sigma_w, "sigma_w"),
        (layout.sigma_b, "sigma_b"),
    ] {
        all.push((segment, name.to_string(), false));
    }
    all
}

fn assert_close(name: &str, actual: &[f32], expected: &[f64], rtol: f64) {
    assert_eq!(actual.len(), expected.len(), "{name}: length");
    let scale = expected
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(1e-3);
    for (i, (&a, &e)) in actual.iter().zip(expected).enumerate() {
        assert!(
            (a as f64 - e).abs() <= rtol * (e.abs() + 0.01 * scale),
            "{name}[{i}]: analytic {a} vs reference {e}"
        );
    }
}

fn check_against_finite_differences(case: &Case) {
    let layout = *case.net.layout();
    let (q, grads) = analytic(case);
    let p64: Vec<f64> = case.net.parameters().iter().map(|&v| v as f64).collect();
    let x64: Vec<f64> = case.x.iter().map(|&v| v as f64).collect();
    assert_close(
        "Q",
        &q,
        &reference_q(&layout, &p64, &x64, case.noise.as_ref()),
        1e-4,
    );

    let h = 1e-6;
    let mut perturbed = p64.clone();
    let mut fd = vec![0.0f64; p64.len()];
    for (i, g) in fd.iter_mut().enumerate() {
        perturbed[i] = p64[i] + h;
        let up = reference_loss(case, &perturbed);
        perturbed[i] = p64[i] - h;
        let down = reference_loss(case, &perturbed);
        perturbed[i] = p64[i];
        *g = (up - down) / (2.0 * h);
    }
    let trunk_factor = layout.heads() as f32;
    for (segment, name, is_trunk) in segments(&layout) {
        let analytic: Vec<f32> = grads
            .tensor(segment)
            .iter()
            .map(|&g| if is_trunk { g * trunk_factor } else { g })
            .collect();
        assert_close(&name, &analytic, &fd[segment.range()], 1e-3);
    }
}

/// The cases each oracle checks, with seeds from `seed` up in this order: Plain, Bootstrap (`heads[0]` heads) and
/// Noisy (under a fixed noise sample) at the paper's widths, then the same kinds (Bootstrap with `heads[1]`) at
/// each of [`OTHER_WIDTHS`] (depths 1 to 4).
fn every_kind_and_width(seed: u64, heads: [usize; 2]) -> Vec<Case> {
    let kinds = |heads| {
        [
            OutputKind::Plain,
            OutputKind::Bootstrap { heads },
            OutputKind::Noisy,
        ]
    };
    let paper = kinds(heads[0]).map(|kind| (kind, &[HIDDEN, HIDDEN][..]));
    let other = OTHER_WIDTHS
        .into_iter()
        .flat_map(|hidden| kinds(heads[1]).map(|kind| (kind, hidden)));
    paper
        .into_iter()
        .chain(other)
        .zip(seed..)
        .map(|((kind, hidden), seed)| {
            let c = case_with(kind, seed, kind == OutputKind::Noisy, hidden);
            assert_eq!(c.net.hidden(), hidden);
            c
        })
        .collect()
}

/// For Bootstrap, the trunk's analytic gradient is scaled by 1/K (the check multiplies it back by K).
#[test]
fn gradients_match_finite_differences_for_every_kind_and_width() {
    for c in every_kind_and_width(1, [4, 3]) {
        check_against_finite_differences(&c);
    }
}

#[test]
fn noisy_without_noise_matches_finite_differences_and_has_zero_sigma_gradients() {
    let c = case(OutputKind::Noisy, 4, false);
    check_against_finite_differences(&c);
    let (_, grads) = analytic(&c);
    let layout = *c.net.layout();
    assert!(grads.tensor(layout.sigma_w).iter().all(|&g| g == 0.0));
    assert!(grads.tensor(layout.sigma_b).iter().all(|&g| g == 0.0));
}

// ---- candle ----

fn var(data: &[f32], shape: &[usize]) -> Var {
    Var::from_slice(data, shape, &Device::Cpu).unwrap()
}

fn to_vec(t: &Tensor) -> Vec<f64> {
    t.flatten_all()
        .unwrap()
        .to_vec1::<f32>()
        .unwrap()
        .into_iter()
        .map(|v| v as f64)
        .collect()
}

/// Columns `cols` of the row-major `[rows][width]` matrix `m`, as a row-major `[rows][cols.len()]` copy.
fn columns(m: &[f32], width: usize, cols: Range<usize>) -> Vec<f32> {
    m.chunks_exact(width)
        .flat_map(|row| row[cols.clone()].to_vec())
        .collect()
}

fn check_against_candle(case: &Case) {
    let layout = *case.net.layout();
    let (d, a, width, heads) = sizes(&layout);
    let n2 = *layout.hidden.last().unwrap();
    let (q, grads) = analytic(case);
    let p = case.net.parameters();
    let t = |s: Segment| &p[s.range()];

    let mut h2 = Tensor::from_slice(&case.x, (BATCH, d), &Device::Cpu).unwrap();
    let mut checks: Vec<(String, Vec<f32>, Var)> = Vec::new();
    let mut n_in = d;
    for (layer, &n) in layout.hidden.iter().enumerate() {
        let w = var(t(layout.fc_w[layer]), &[n_in, n]);
        let b = var(t(layout.fc_b[layer]), &[n]);
        h2 = h2
            .matmul(&w)
            .unwrap()
            .broadcast_add(&b)
            .unwrap()
            .relu()
            .unwrap();
        let name = |part: &str| format!("fc{}_{part}", layer + 1);
        checks.push((name("w"), grads.tensor(layout.fc_w[layer]).to_vec(), w));
        checks.push((name("b"), grads.tensor(layout.fc_b[layer]).to_vec(), b));
        n_in = n;
    }
    let loss_weights = |k: usize| {
        Tensor::from_slice(
            &case.w[k * BATCH * a..(k + 1) * BATCH * a],
            (BATCH, a),
            &Device::Cpu,
        )
        .unwrap()
    };

    let mut q_parts = Vec::new();
    let mut loss = Tensor::zeros((), candle_core::DType::F32, &Device::Cpu).unwrap();
    match layout.kind {
        OutputKind::Plain | OutputKind::Bootstrap { .. } => {
            // Same forward value, gradient into the trunk scaled by 1/K (a backward hook in PyTorch).
            let scale = 1.0 / heads as f64;
            let h2_hooked = (h2.affine(scale, 0.0).unwrap()
                + h2.detach().affine(1.0 - scale, 0.0).unwrap())
            .unwrap();
            for k in 0..heads {
                let cols = k * a..(k + 1) * a;
                let wk = var(&columns(t(layout.out_w), width, cols.clone()), &[n2, a]);
                let bk = var(&t(layout.out_b)[cols.clone()], &[a]);
                let qk = h2_hooked.matmul(&wk).unwrap().broadcast_add(&bk).unwrap();
                loss = (loss + (&qk * &loss_weights(k)).unwrap().sum_all().unwrap()).unwrap();
                q_parts.push(qk);
                checks.push((
                    format!("head{k}_w"),
                    columns(grads.tensor(layout.out_w), width, cols.clone()),
                    wk,
                ));
                checks.push((
                    format!("head{k}_b"),
                    grads.tensor(layout.out_b)[cols].to_vec(),
                    bk,
                ));
            }
        }
        OutputKind::Noisy => {
            let noise = case
                .noise
                .clone()
                .unwrap_or_else(|| NoiseSample::with_inputs(n2, a));
            let eps_in = Tensor::from_slice(noise.input_factors(), (1, n2), &Device::Cpu).unwrap();
            let eps_out = Tensor::from_slice(noise.output_factors(), (a, 1), &Device::Cpu).unwrap();
            let eps_w = eps_out.matmul(&eps_in).unwrap();
            let eps_b = eps_out.flatten_all().unwrap();
            let mu_w = var(t(layout.out_w), &[a, n2]);
            let sigma_w = var(t(layout.sigma_w), &[a, n2]);
            let mu_b = var(t(layout.out_b), &[a]);
            let sigma_b = var(t(layout.sigma_b), &[a]);
            let weight = (mu_w.as_tensor() + (sigma_w.as_tensor() * &eps_w).unwrap()).unwrap();
            let bias = (mu_b.as_tensor() + (sigma_b.as_tensor() * &eps_b).unwrap()).unwrap();
            let q0 = h2
                .matmul(&weight.t().unwrap())
                .unwrap()
                .broadcast_add(&bias)
                .unwrap();
            loss = (&q0 * &loss_weights(0)).unwrap().sum_all().unwrap();
            q_parts.push(q0);
            for (name, segment, variable) in [
                ("mu_w", layout.out_w, mu_w),
                ("sigma_w", layout.sigma_w, sigma_w),
                ("mu_b", layout.out_b, mu_b),
                ("sigma_b", layout.sigma_b, sigma_b),
            ] {
                checks.push((name.to_string(), grads.tensor(segment).to_vec(), variable));
            }
        }
    }
    let candle_q: Vec<f64> = q_parts.iter().flat_map(to_vec).collect();
    assert_close("Q", &q, &candle_q, 1e-4);
    let store = loss.backward().unwrap();
    for (name, ours, variable) in checks {
        let reference = to_vec(store.get(variable.as_tensor()).expect("candle gradient"));
        assert_close(&name, &ours, &reference, 1e-4);
    }
}

/// For Bootstrap, candle's network carries the trunk hook (1/K gradient).
#[test]
fn gradients_match_candle_for_every_kind_and_width() {
    for c in every_kind_and_width(31, [10, 4]) {
        check_against_candle(&c);
    }
}

// ---- consistency of the other entry points ----

#[test]
/// Bit for bit: lockstep evaluation (one batched forward for all test episodes) must choose the same
/// actions as acting on each state alone.
fn single_state_forward_equals_the_batch_forward_bit_for_bit_for_every_kind() {
    for ((kind, with_noise), hidden) in [
        (OutputKind::Plain, false),
        (OutputKind::Bootstrap { heads: 3 }, false),
        (OutputKind::Noisy, false),
        (OutputKind::Noisy, true),
    ]
    .into_iter()
    .flat_map(|k| {
        std::iter::once(&[HIDDEN, HIDDEN][..])
            .chain(OTHER_WIDTHS)
            .map(move |h| (k, h))
    }) {
        let c = case_with(kind, 8, with_noise, hidden);
        let n2 = *hidden.last().unwrap();
        let mut ws = Workspace::new(&c.net, BATCH);
        let q = c
            .net
            .forward(&c.x, BATCH, c.noise.as_ref(), &mut ws)
            .to_vec();
        let (heads, a) = (kind.heads(), N_ACTIONS);
        for b in 0..BATCH {
            let mut single = vec![0.0f32; heads * a];
            let mut features = vec![0.0f32; n2];
            c.net.q_values_single_with_features(
                &c.x[b * OBS_DIM..(b + 1) * OBS_DIM],
                c.noise.as_ref(),
                &mut single,
                &mut features,
            );
            for k in 0..heads {
                for act in 0..a {
                    let batch_value = q[(k * BATCH + b) * a + act];
                    assert_eq!(
                        single[k * a + act].to_bits(),
                        batch_value.to_bits(),
                        "{kind:?} b{b} k{k} a{act}"
                    );
                }
            }
            for (f, g) in features.iter().zip(&ws.features()[b * n2..(b + 1) * n2]) {
                assert_eq!(f.to_bits(), g.to_bits());
            }
        }
    }
}

#[test]
fn workspace_reuse_with_a_smaller_batch_gives_the_same_gradients() {
    let c = case(OutputKind::Bootstrap { heads: 2 }, 9, false);
    let (_, expected) = analytic(&c);
    // A larger earlier pass must leave nothing behind that the smaller one picks up.
    let mut ws = Workspace::new(&c.net, 16);
    let big_x: Vec<f32> = (0..16 * OBS_DIM).map(|i| (i as f32).sin() * 3.0).collect();
    let big_dq = vec![1.0f32; 2 * 16 * N_ACTIONS];
    let mut grads = Grads::new(&c.net);
    c.net.forward(&big_x, 16, None, &mut ws);
    c.net.backward(&mut ws, &big_dq, &mut grads);
    c.net.forward(&c.x, BATCH, None, &mut ws);
    c.net.backward(&mut ws, &c.w, &mut grads);
    assert_eq!(grads.as_slice(), expected.as_slice());
}

#[test]
fn copy_from_makes_an_identical_network() {
    let mut rng = Pcg64::seed_from_u64(10);
    let online = QNet::new(4, 3, OutputKind::Noisy, &mut rng);
    let mut target = QNet::new(4, 3, OutputKind::Noisy, &mut rng);
    assert_ne!(online.parameters(), target.parameters());
    target.copy_from(&online);
    assert_eq!(online.parameters(), target.parameters());
}

#[test]
fn initialisation_follows_the_documented_ranges() {
    let mut rng = Pcg64::seed_from_u64(11);
    let net = QNet::new(6, 4, OutputKind::Noisy, &mut rng);
    let l = *net.layout();
    let p = net.parameters();
    let within = |s: Segment, bound: f32| p[s.range()].iter().all(|v| v.abs() <= bound);
    assert!(within(l.fc_w[0], 1.0 / 6f32.sqrt()) && within(l.fc_b[0], 1.0 / 6f32.sqrt()));
    assert!(within(l.fc_w[1], 0.125) && within(l.out_w, 0.125) && within(l.out_b, 0.125));
    assert!(
        p[l.sigma_w.range()]
            .iter()
            .chain(&p[l.sigma_b.range()])
            .all(|&s| s == 0.5 / 8.0)
    );
    // The draws fill the range (not, say, a tenth of it).
    assert!(p[l.fc_w[1].range()].iter().any(|v| v.abs() > 0.12));

    // Bootstrap heads are initialised independently: no two heads are equal.
    let boot = QNet::new(6, 4, OutputKind::Bootstrap { heads: 3 }, &mut rng);
    let bl = *boot.layout();
    let w = &boot.parameters()[bl.out_w.range()];
    let head = |k: usize| columns(w, bl.out_width, k * 4..(k + 1) * 4);
    assert_ne!(head(0), head(1));
    assert_ne!(head(1), head(2));
}

#[test]
fn argmax_takes_the_first_maximum() {
    assert_eq!(argmax(&[1.0, 3.0, 3.0, -1.0]), 1);
    assert_eq!(argmax(&[-2.0]), 0);
    assert_eq!(argmax(&[0.0, -1.0, 5.0]), 2);
}
