#!/usr/bin/env python3
"""JAX/XLA's side of `make bench-peers`: conv rows, the three nets per frame, training steps.

    python benches/peers/jax_bench.py [conv] [nets] [train]

The nets are the independent JAX re-implementation the audits use (tests/fixtures/gen_nets.py),
float32, jit-compiled; a training step is forward + backward + optax.adam of GeometryNet with
the MSE loss (as benches/peers.rs), on 32 LR 16x16 patches. XLA uses every core.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "tests", "fixtures"))
import rows  # noqa: E402
import gen_nets as g  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402

jax.config.update("jax_enable_x64", False)


def block(f):
    return lambda: jax.block_until_ready(f())


def main():
    want = rows.groups(sys.argv[1:])
    rng = np.random.default_rng(0)
    f32 = lambda *s: jnp.asarray(rng.uniform(-0.5, 0.5, s), jnp.float32)  # noqa: E731
    if "conv" in want:
        conv = jax.jit(lambda x, w, b: g.conv(x, w, b, "zero"))
        for n, c, o, h, w in rows.CONVS:
            x, wt, b = f32(n, c, h, w), f32(o, c, 3, 3), f32(o)
            rows.emit(rows.conv_row(n, c, o, h, w), rows.median_ms(block(lambda: conv(x, wt, b))))
    for name, (c, nb) in rows.CONFIGS.items():
        g.C, g.B = c, nb
        params = {k: {n: jnp.asarray(v) for n, v in g.init(k, rng).items()} for k in ("geometry", "boundary", "enhance")}
        if "nets" in want:
            for size in rows.NET_SIZES:
                mh = jnp.asarray(g.cubic_matrix(size, 2 * size, -0.5), jnp.float32)

                @jax.jit
                def nets(p, x, mh=mh):
                    u = jnp.einsum("oh,nchw,pw->ncop", mh, x, mh)
                    return (u, g.forward(p["geometry"], x, "geometry", "zero"),
                            jax.nn.sigmoid(g.forward(p["boundary"], x, "boundary", "zero")),
                            jax.nn.sigmoid(g.forward(p["enhance"], x, "enhance", "zero")))

                x = jnp.asarray(rng.uniform(0, 1, (1, 3, size, size)), jnp.float32)
                ms = rows.median_ms(block(lambda: nets(params, x)))
                rows.emit(rows.nets_row(name, size), ms, precision="fp32")
        if "train" in want:
            bsz, p = rows.TRAIN_BATCH, rows.TRAIN_PATCH
            x = jnp.asarray(rng.uniform(size=(bsz, 3, p, p)), jnp.float32)
            u = jnp.asarray(g.bicubic(np.asarray(x, np.float64), 2), jnp.float32)
            t = jnp.asarray(rng.uniform(size=u.shape), jnp.float32)
            opt = optax.adam(1e-4)
            state = {"p": params["geometry"], "s": opt.init(params["geometry"])}

            @jax.jit
            def step(q, s):
                loss, grads = jax.value_and_grad(
                    lambda q: jnp.mean((u + g.forward(q, x, "geometry", "zero") - t) ** 2))(q)
                upd, s = opt.update(grads, s, q)
                return optax.apply_updates(q, upd), s, loss

            def one():
                state["p"], state["s"], loss = step(state["p"], state["s"])
                loss.block_until_ready()

            rows.emit(rows.train_row(name), rows.median_ms(one, min_calls=5, min_secs=2.0))


if __name__ == "__main__":
    main()
