//! GeometryNet / BoundaryNet / EnhanceNet against an independent JAX implementation
//! (tests/fixtures/gen_nets.py, float64): forward, every layer's activation, the loss, every
//! parameter gradient, for the `tiny` config with both paddings; and 10 Adam steps of
//! GeometryNet against optax.adam (loss trajectory and final weights).

#[path = "common/close.rs"]
mod close;
#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::{read_npz, NpzEntries};
use anisocb::nn::config::parse_padding;
use anisocb::nn::weights::load_net;
use anisocb::nn::{GeometryNet, MapNet, NetConfig, NetKind, Trunk};
use anisocb::ops::{AdamParams, Cpu, Ops};
use anisocb::Tensor;
use close::assert_close;
use std::path::PathBuf;
use tempdir::TempDir;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/nets").join(name)
}

fn load(name: &str) -> NpzEntries {
    read_npz(&fixture(name)).unwrap()
}

fn cases() -> Vec<(NetKind, &'static str)> {
    let mut v = Vec::new();
    for k in NetKind::ALL {
        for p in ["zero", "replicate"] {
            v.push((k, p));
        }
    }
    v
}

fn load_case(kind: NetKind, pad: &str) -> (Trunk, NpzEntries) {
    let case = format!("{}_{pad}", kind.name());
    let cfg = NetConfig::tiny().with_padding(parse_padding(pad).unwrap());
    let trunk = load_net(&fixture(&format!("{case}.npz")), Some((kind, cfg))).unwrap();
    (trunk, load(&format!("{case}_io.npz")))
}

#[test]
fn forward_loss_and_gradients_match_jax_for_all_nets_and_paddings() {
    let ops: &dyn Ops = &Cpu;
    for (kind, pad) in cases() {
        let case = format!("{}_{pad}", kind.name());
        let (trunk, io) = load_case(kind, pad);
        let x = io.array("input").unwrap();
        let target = io.array("target").unwrap();
        let want_loss = io.array("loss").unwrap().data[0];
        let mut grads = trunk.zeros_like();
        let loss = if kind == NetKind::Geometry {
            let net = GeometryNet { trunk };
            let (u, r) = net.forward(ops, x).unwrap();
            assert_close(&format!("{case} U"), &u, io.array("u").unwrap(), 1e-5, 1e-5);
            assert_close(&format!("{case} R"), &r, io.array("r").unwrap(), 1e-5, 1e-4);
            net.loss(ops, x, &u, target, Some(&mut grads)).unwrap()
        } else {
            let net = MapNet { trunk };
            let z = net.logits(ops, x).unwrap();
            assert_close(&format!("{case} logits"), &z, io.array("logits").unwrap(), 1e-5, 1e-4);
            let pw = io.array("pos_weight").unwrap().data[0];
            net.loss(ops, x, target, pw, Some(&mut grads)).unwrap()
        };
        assert!(
            (loss - want_loss).abs() <= 1e-6 + 1e-5 * want_loss.abs(),
            "{case}: loss {loss} vs JAX {want_loss}"
        );
        let want = load(&format!("{case}_grads.npz"));
        let names: Vec<String> = grads.params().into_iter().map(|(n, _)| n).collect();
        assert_eq!(names.len(), want.arrays.len(), "{case}: number of gradient arrays");
        for (name, g) in grads.params() {
            assert_close(&format!("{case} d{name}"), g, want.array(&name).unwrap(), 1e-6, 1e-4);
        }
    }
}

#[test]
fn every_layer_activation_matches_jax_by_name() {
    let ops: &dyn Ops = &Cpu;
    for (kind, pad) in cases() {
        let case = format!("{}_{pad}", kind.name());
        let (trunk, io) = load_case(kind, pad);
        let want = load(&format!("{case}_acts.npz"));
        let mut seen = Vec::new();
        trunk.forward_observed(ops, io.array("input").unwrap(), &mut |name, t| {
            let w = want.array(name).unwrap_or_else(|| panic!("{case}: JAX has no layer '{name}'"));
            assert_close(&format!("{case} {name}"), t, w, 1e-5, 1e-4);
            seen.push(name.to_string());
        });
        let want_names: Vec<&String> = want.arrays.iter().map(|(n, _)| n).collect();
        assert_eq!(seen.len(), want_names.len(), "{case}: layers {seen:?} vs JAX {want_names:?}");
    }
}

#[test]
fn ten_adam_steps_of_geometry_net_follow_optax() {
    let ops: &dyn Ops = &Cpu;
    let (trunk, io) = load_case(NetKind::Geometry, "zero");
    let reference = load("adam.npz");
    let hp = AdamParams { lr: reference.array("lr").unwrap().data[0], ..AdamParams::default() };
    let (x, hr) = (io.array("input").unwrap(), io.array("target").unwrap());
    let mut net = GeometryNet { trunk };
    let (u, _) = net.forward(ops, x).unwrap();
    let mut m = net.trunk.zeros_like();
    let mut v = net.trunk.zeros_like();
    let mut grads = net.trunk.zeros_like();
    let want_losses = reference.array("losses").unwrap();
    for step in 1..=10u64 {
        grads.fill_zero();
        let loss = net.loss(ops, x, &u, hr, Some(&mut grads)).unwrap();
        let want = want_losses.data[step as usize - 1];
        println!("step {step}: loss {loss:.7} optax {want:.7}");
        assert!((loss - want).abs() <= 1e-6 + 1e-4 * want, "step {step}: loss {loss} vs optax {want}");
        let gs: Vec<Tensor> = grads.params().into_iter().map(|(_, t)| t.clone()).collect();
        for (((p, g), m), v) in
            net.trunk.params_mut().into_iter().zip(&gs).zip(m.params_mut()).zip(v.params_mut())
        {
            ops.adam_update(&mut p.data, &g.data, &mut m.data, &mut v.data, step, &hp);
        }
    }
    for (name, p) in net.trunk.params() {
        assert_close(&format!("final {name}"), p, reference.array(&name).unwrap(), 2e-5, 1e-4);
    }
}

#[cfg(feature = "cli")]
#[test]
fn audit_command_writes_every_layer_as_npy_matching_jax() {
    let (_, io) = load_case(NetKind::Geometry, "replicate");
    let dir = TempDir::new("audit-cli");
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("x.npy");
    anisocb::io::write_npy(&input, io.array("input").unwrap()).unwrap();
    let out = dir.join("acts");
    let weights = fixture("geometry_replicate.npz");
    let args =
        ["anisocb", "audit", "--weights", weights.to_str().unwrap(), "--input", input.to_str().unwrap()];
    let code = anisocb::app::main_with_args(args.into_iter().chain(["--out", out.to_str().unwrap()]));
    assert_eq!(code, 0);
    let want = load("geometry_replicate_acts.npz");
    for (name, w) in &want.arrays {
        let got = anisocb::io::read_npy(&out.join(format!("{name}.npy"))).unwrap();
        assert_close(&format!("audit {name}"), &got, w, 1e-5, 1e-4);
    }
    let u = anisocb::io::read_npy(&out.join("interp.npy")).unwrap();
    assert_close("audit interp", &u, io.array("u").unwrap(), 1e-5, 1e-5);
}
