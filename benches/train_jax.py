"""JAX/XLA (CPU) baseline for benches/train.rs: the same GeometryNet (the JAX reference of
tests/fixtures/gen_nets.py), float32, jit-compiled train step (forward + backward + optax.adam)
on a batch of 32 LR 16x16 patches, and inference per 32x32 frame.
Run: python3 benches/train_jax.py [small|paper]"""
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures"))
import gen_nets as g  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402

jax.config.update("jax_enable_x64", False)

for name, (C, B) in {"small": (32, 4), "paper": (64, 10)}.items():
    if len(sys.argv) > 1 and sys.argv[1] != name:
        continue
    g.C, g.B = C, B
    rng = np.random.default_rng(0)
    p = {k: jnp.asarray(v, jnp.float32) for k, v in g.init("geometry", rng).items()}
    x = jnp.asarray(rng.uniform(size=(32, 3, 16, 16)), jnp.float32)
    u = jnp.asarray(g.bicubic(np.asarray(x, np.float64), 2), jnp.float32)
    t = jnp.asarray(rng.uniform(size=u.shape), jnp.float32)
    opt = optax.adam(1e-4)
    state = opt.init(p)

    @jax.jit
    def step(p, state):
        loss, grads = jax.value_and_grad(lambda q: jnp.mean((u + g.forward(q, x, "geometry", "zero") - t) ** 2))(p)
        upd, state = opt.update(grads, state, p)
        return optax.apply_updates(p, upd), state, loss

    p, state, loss = step(p, state)
    loss.block_until_ready()
    n = 3 if name == "paper" else 8
    t0 = time.perf_counter()
    for _ in range(n):
        p, state, loss = step(p, state)
    loss.block_until_ready()
    s = (time.perf_counter() - t0) / n
    print(f"{name:>5} JAX GeometryNet train: {32 / s:.1f} samples/s ({s * 1e3:.1f} ms/step)")
    frame = jnp.asarray(rng.uniform(size=(1, 3, 32, 32)), jnp.float32)
    fwd = jax.jit(lambda q, f: g.forward(q, f, "geometry", "zero"))
    fwd(p, frame).block_until_ready()
    t0 = time.perf_counter()
    for _ in range(10):
        fwd(p, frame).block_until_ready()
    print(f"{name:>5} JAX inference 32x32 -> 64x64: GeometryNet {(time.perf_counter() - t0) * 100:.2f} ms/frame")
