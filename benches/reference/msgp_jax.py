"""A JAX (float64, jit) reference of msgp's open-loop MSGP loss.

Mirrors crates/msgp-core/src/{gp,moments,rollout,loss}.rs step by step:

* parameters (flat vector, `GpParams::to_flat` order, matrices row-major):
  pseudo-inputs X (m x D), pseudo-targets Y (m x E), log-lengthscales (E x D),
  log sf2 (E), process-noise theta_x (E), observation-noise theta_y (E);
  sigma^2 = floor + exp(theta) for both noises;
* per output a: Kt = K_a(X, X) + sx2_a I (SE-ARD, 1/l^2 = exp(-2 log l)), beta = Kt^-1 y_a,
  Kinv = Kt^-1 (symmetrised);
* exact PILCO moment matching of the GP at the window x ~ N(mu, Sigma): mean M_a, full latent
  covariance S_ab (cross terms, - tr(Kinv Q) + sf2 on the diagonal) and V = Sigma^-1 Cov(x, f);
* open-loop rollout over the NARX window: x_{t+1} = f + eps_x; observation y = x + eps_y;
  the window starts from the first max(l_y, l_u) samples with latent outputs N(y, sy2) and
  measured inputs (zero variance), then shifts the new latent output and the measured input in;
* loss = sum_t 1/2 [r' V^-1 r + log|V| + d_y log 2 pi], V = S + diag(sx2) + diag(sy2),
  plus the default complexity term (PseudoDataNll): sum_a 1/2 [y_a' beta_a + log|Kt_a| + m log 2 pi].

No jitter is ever added here; the Rust dump reports how many factorisations needed jitter
(the comparison requires zero).
"""

import os

os.environ.setdefault(
    "XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.scipy.linalg as jsl  # noqa: E402
import numpy as np  # noqa: E402
from jax import lax  # noqa: E402

jax.config.update("jax_enable_x64", True)

LN_2PI = 1.837_877_066_409_345_3


def shift_map(ly, lu, dy, du):
    """`NarxSpec::shift_map`: entry i of the next window is entry sel[i] of [window, x_new, u_new]."""
    d = ly * dy + lu * du
    sel = [0] * d
    for j in range(dy):
        sel[j] = d + j
    for k in range(1, ly):
        for j in range(dy):
            sel[k * dy + j] = (k - 1) * dy + j
    if lu > 0:
        for j in range(du):
            sel[ly * dy + j] = d + dy + j
        for k in range(1, lu):
            for j in range(du):
                sel[ly * dy + k * du + j] = ly * dy + (k - 1) * du + j
    return np.array(sel, dtype=np.int64)


def unflatten(flat, m, d, e):
    i = 0
    X = flat[i : i + m * d].reshape(m, d)
    i += m * d
    Y = flat[i : i + m * e].reshape(m, e)
    i += m * e
    logl = flat[i : i + e * d].reshape(e, d)
    i += e * d
    lsf2 = flat[i : i + e]
    i += e
    lsx = flat[i : i + e]
    i += e
    lsy = flat[i : i + e]
    return X, Y, logl, lsf2, lsx, lsy


def chol_logdet(L):
    return 2.0 * jnp.sum(jnp.log(jnp.diag(L)))


def prepare(flat, m, d, e, floor):
    X, Y, logl, lsf2, lsx, lsy = unflatten(flat, m, d, e)
    inv_l2 = jnp.exp(-2.0 * logl)  # E x D
    sf2 = jnp.exp(lsf2)
    sx2 = jnp.exp(lsx) + floor
    sy2 = jnp.exp(lsy) + floor
    diff = X[:, None, :] - X[None, :, :]  # m x m x D
    eye = jnp.eye(m)
    outs = []
    for a in range(e):
        K = sf2[a] * jnp.exp(-0.5 * jnp.sum(diff * diff * inv_l2[a], axis=-1))
        Kt = K + sx2[a] * eye
        L = jnp.linalg.cholesky(Kt)
        beta = jsl.cho_solve((L, True), Y[:, a])
        kinv = jsl.cho_solve((L, True), eye)
        kinv = 0.5 * (kinv + kinv.T)
        outs.append(dict(beta=beta, kinv=kinv, logdet=chol_logdet(L)))
    return dict(X=X, Y=Y, inv_l2=inv_l2, sf2=sf2, sx2=sx2, sy2=sy2, outs=outs)


def moment_match(gp, mu, Sig):
    """Returns (M (E), S (E x E), V (D x E)); see crates/msgp-core/src/moments.rs."""
    X, inv_l2, sf2 = gp["X"], gp["inv_l2"], gp["sf2"]
    e = inv_l2.shape[0]
    d = X.shape[1]
    eye = jnp.eye(d)
    nu = X - mu  # m x D
    means, vcols, lks = [], [], []
    for a in range(e):
        s = jnp.sqrt(inv_l2[a])
        Shat = eye + s[:, None] * Sig * s[None, :]
        L = jnp.linalg.cholesky(Shat)
        nut = nu * s  # m x D, row i = diag(s) nu_i
        w = jsl.cho_solve((L, True), nut.T)  # D x m
        quad = jnp.sum(nut.T * w, axis=0)
        plain = jnp.sum(nut * nut, axis=1)
        lsf2 = jnp.log(sf2[a])
        lks.append(lsf2 - 0.5 * plain)
        q = jnp.exp(lsf2 - 0.5 * (quad + chol_logdet(L)))
        bq = gp["outs"][a]["beta"] * q
        means.append(jnp.sum(bq))
        vcols.append(s * (w @ bq))
    M = jnp.stack(means)
    V = jnp.stack(vcols, axis=1)
    S = [[None] * e for _ in range(e)]
    for a in range(e):
        for b in range(a, e):
            sp = jnp.sqrt(inv_l2[a] + inv_l2[b])
            St = eye + sp[:, None] * Sig * sp[None, :]
            L = jnp.linalg.cholesky(St)
            N = eye - jsl.cho_solve((L, True), eye)
            At = nu * (inv_l2[a] / sp)  # m x D
            Bt = nu * (inv_l2[b] / sp)
            NB = Bt @ N  # rows N b_j (N symmetric)
            G = At @ NB.T  # m x m
            ua = lks[a] + 0.5 * jnp.sum(At * (At @ N), axis=1)
            ub = lks[b] + 0.5 * jnp.sum(Bt * NB, axis=1) - 0.5 * chol_logdet(L)
            Q = jnp.exp(ua[:, None] + ub[None, :] + G)
            oa, ob = gp["outs"][a], gp["outs"][b]
            v = oa["beta"] @ (Q @ ob["beta"]) - M[a] * M[b]
            if a == b:
                v = v + sf2[a] - jnp.sum(oa["kinv"] * Q)
            S[a][b] = v
            S[b][a] = v
    S = jnp.stack([jnp.stack(row) for row in S])
    return M, S, V


def make_loss(problem):
    """Returns (loss(flat, y, u), flat0, y, u) for a problem dumped by `msgp_perf dump`."""
    sp = problem["spec"]
    ly, lu, dy, du = sp["ly"], sp["lu"], sp["dy"], sp["du"]
    sh = problem["shape"]
    m, d, e = sh["m"], sh["d"], sh["e"]
    assert e == dy and d == ly * dy + lu * du
    if problem["complexity"] != "PseudoDataNll":
        raise ValueError("only the default complexity term (PseudoDataNll) is implemented")
    floor = float(problem["noise_floor"])
    sel = shift_map(ly, lu, dy, du)
    t0 = max(ly, lu)

    def loss(flat, y, u):
        gp = prepare(flat, m, d, e, floor)
        # initial window x_{t0-1}
        mu0 = jnp.concatenate(
            [y[t0 - 1 - k] for k in range(ly)] + [u[t0 - 1 - k] for k in range(lu)]
        )
        sig_diag = jnp.concatenate(
            [gp["sy2"] for _ in range(ly)] + [jnp.zeros(du) for _ in range(lu)]
        )
        Sig0 = jnp.diag(sig_diag)
        noise_x = jnp.diag(gp["sx2"])
        noise_y = jnp.diag(gp["sy2"])
        zeros_u = jnp.zeros((du, du))

        def step(carry, xs):
            mu, Sig = carry
            y_t, u_t = xs
            M, S, V = moment_match(gp, mu, Sig)
            xcov = S + noise_x
            ycov = xcov + noise_y
            L = jnp.linalg.cholesky(ycov)
            z = jsl.solve_triangular(L, y_t - M, lower=True)
            nll = 0.5 * (jnp.dot(z, z) + chol_logdet(L) + dy * LN_2PI)
            # augmented [window, x_{t+1}, u_{t+1}] and the shift
            amu = jnp.concatenate([mu, M, u_t])
            C = Sig @ V  # D x E
            top = jnp.concatenate([Sig, C, jnp.zeros((d, du))], axis=1)
            mid = jnp.concatenate([C.T, xcov, jnp.zeros((dy, du))], axis=1)
            bot = jnp.concatenate([jnp.zeros((du, d)), jnp.zeros((du, dy)), zeros_u], axis=1)
            acov = jnp.concatenate([top, mid, bot], axis=0)
            mu_n = amu[sel]
            Sig_n = acov[sel][:, sel]
            Sig_n = 0.5 * (Sig_n + Sig_n.T)
            return (mu_n, Sig_n), nll

        (_, _), nlls = lax.scan(step, (mu0, Sig0), (y[t0:], u[t0:]))
        comp = 0.0
        for a in range(e):
            o = gp["outs"][a]
            comp = comp + 0.5 * (jnp.dot(gp["Y"][:, a], o["beta"]) + o["logdet"] + m * LN_2PI)
        return jnp.sum(nlls) + comp

    flat0 = jnp.asarray(np.array(problem["flat"], dtype=np.float64))
    y = jnp.asarray(np.array(problem["y"], dtype=np.float64).reshape(-1, dy))
    u = jnp.asarray(np.array(problem["u"], dtype=np.float64).reshape(-1, du))
    return loss, flat0, y, u
