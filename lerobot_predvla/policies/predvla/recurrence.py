"""Fused recurrence of Eqs. 3-6 with a hand-written backpropagation through time.

Every input-independent pre-activation term P^l_t (U^l c^l_{q,t}, W_lang l, b^l, any extra input) is computed
for the whole sequence before the loop. Inside the loop each module applies one matmul to its concatenated
inputs, e.g. [W_rec | W_td | W_ba | W_bq] [d^V_{t-1}; d^T_t; a_{t-1}; q_{t-1}], and stores what the backward
needs in preallocated buffers. The backward runs the recurrence in reverse with input-gradient matmuls only,
then forms each weight gradient with one matmul over all steps. Pure tensor code: runs on any device.
"""

from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import Tensor

T, V, A_TOP, A_BOTTOM = range(4)


class FusedWeights(NamedTuple):
    """Per-module weights concatenated along their inputs (built from the parameters under autograd)."""

    w_t: Tensor  # (d_T, d_T): W_rec^T
    w_v: Tensor  # (d_V, d_V + d_T [+ a + q]): [W_rec^V | W_td^V | W_ba | W_bq] (Eqs. 3, 6)
    w_at: Tensor  # (d_At, d_At + d_T [+ z]): [W_rec^At | W_td^At | W_top] (Eqs. 3, 5)
    w_va: Tensor | None  # (z, d_V): W_VA (Eq. 5), None without the bottleneck (ablation A2)
    w_ab: Tensor  # (d_Ab, d_Ab + d_At): [W_rec^Ab | W_td^Ab]
    w1: Tensor  # (2H, d_Ab): first layers of the q and action heads, stacked
    b1: Tensor
    w2: Tensor  # (q + K + K a, 2H): block-diagonal second layers -> [q_hat | logits | means]
    b2: Tensor


class Meta(NamedTuple):
    alpha: tuple[float, float, float, float]  # 1 / tau_l
    efference: bool  # the V module reads [a_{t-1}, q_{t-1}] (Eq. 6)
    num_mixtures: int
    action_dim: int
    proprio_dim: int


def _forward(meta: Meta, p: list[Tensor], h: list[Tensor], d: list[Tensor], a: Tensor, q: Tensor, w: FusedWeights):
    """The loop; returns the outputs and the buffers the backward reads."""
    steps, batch = p[T].shape[:2]
    nq, k, na = meta.proprio_dim, meta.num_mixtures, meta.action_dim
    # Buffers: D^l holds d^l_0..d^l_T (row 0 = initial state); G^l = tanh(pre-activation); IN^l = matmul inputs.
    dbuf = [x.new_empty((steps + 1, *x.shape)) for x in d]
    for buf, x in zip(dbuf, d, strict=True):
        buf[0] = x
    gbuf = [x.new_empty((steps, *x.shape)) for x in d]
    inbuf = [None] + [a.new_empty((steps, batch, w_.shape[1])) for w_ in (w.w_v, w.w_at, w.w_ab)]
    y1 = a.new_empty((steps, batch, w.w1.shape[0]))
    out = a.new_empty((steps, batch, w.w2.shape[0]))
    abuf = a.new_empty((steps, batch, na))
    dsteps = [buf[1:].unbind(0) for buf in dbuf]
    gsteps = [buf.unbind(0) for buf in gbuf]
    insteps = [None] + [buf.unbind(0) for buf in inbuf[1:]]
    psteps = [x.unbind(0) for x in p]
    wt = [w.w_t.t(), w.w_v.t(), w.w_at.t(), w.w_ab.t()]
    w_va_t = None if w.w_va is None else w.w_va.t()
    w1_t, w2_t = w.w1.t(), w.w2.t()
    a_t, a_v, a_at, a_ab = meta.alpha
    d_t, d_v, d_at, d_ab = d
    h_t, h_v, h_at, h_ab = h
    index = []
    # Per-step views of the heads' output [q_hat | logits | means] and of the executed action.
    q_s, logits_s = out[..., :nq].unbind(0), out[..., nq : nq + k].unbind(0)
    means_s = out[..., nq + k :].unflatten(-1, (k, na)).unbind(0)
    a_s, a_out = abuf.unbind(0), abuf.unsqueeze(2).unbind(0)
    for i, (y1_i, out_i) in enumerate(zip(y1.unbind(0), out.unbind(0), strict=True)):
        # T (Eq. 4): h = (1 - 1/tau) h + 1/tau tanh(P + W_rec d_{t-1}), d = tanh(h).
        g = torch.addmm(psteps[T][i], d_t, wt[T], out=gsteps[T][i]).tanh_()
        h_t = torch.lerp(h_t, g, a_t)
        d_t = torch.tanh(h_t, out=dsteps[T][i])
        # V (Eqs. 3, 6).
        parts = (d_v, d_t, a, q) if meta.efference else (d_v, d_t)
        g = torch.addmm(psteps[V][i], torch.cat(parts, 1, out=insteps[V][i]), wt[V], out=gsteps[V][i]).tanh_()
        h_v = torch.lerp(h_v, g, a_v)
        d_v = torch.tanh(h_v, out=dsteps[V][i])
        # A_top (Eqs. 3, 5): z = W_VA d^V.
        parts = (d_at, d_t) if w_va_t is None else (d_at, d_t, torch.mm(d_v, w_va_t))
        g = torch.addmm(psteps[A_TOP][i], torch.cat(parts, 1, out=insteps[A_TOP][i]), wt[A_TOP],
                        out=gsteps[A_TOP][i]).tanh_()
        h_at = torch.lerp(h_at, g, a_at)
        d_at = torch.tanh(h_at, out=dsteps[A_TOP][i])
        # A_bottom (Eq. 3).
        g = torch.addmm(psteps[A_BOTTOM][i], torch.cat((d_ab, d_at), 1, out=insteps[A_BOTTOM][i]), wt[A_BOTTOM],
                        out=gsteps[A_BOTTOM][i]).tanh_()
        h_ab = torch.lerp(h_ab, g, a_ab)
        d_ab = torch.tanh(h_ab, out=dsteps[A_BOTTOM][i])
        # Heads: q_hat and the mode of the GMM (mean of the highest-weight component), fed back by Eq. 6.
        torch.addmm(w.b2, torch.relu_(torch.addmm(w.b1, d_ab, w1_t, out=y1_i)), w2_t, out=out_i)
        idx = logits_s[i].argmax(1, keepdim=True).unsqueeze(2).expand(batch, 1, na)
        torch.gather(means_s[i], 1, idx, out=a_out[i]).tanh_()
        q, a = q_s[i], a_s[i]
        index.append(idx)
    return (dbuf, gbuf, inbuf, y1, out, abuf, torch.stack(index)), (h_t, h_v, h_at, h_ab)


def weight_gradients(
    needs: tuple[bool, ...], w: FusedWeights, gx: list[Tensor], dbuf: list[Tensor], inbuf: list[Tensor], y1: Tensor,
    gy1: Tensor, gout: Tensor,
) -> list[Tensor | None]:
    """Each weight's gradient, where `needs` (one flag per `FusedWeights` field) asks for it, as one matmul over all
    steps: the pre-activation gradients gx^l against the matmul inputs (D^T_{t-1}, IN^V, IN^At, IN^Ab), the
    heads' output and hidden-layer gradients against their inputs."""
    grad_w: list[Tensor | None] = [None] * len(w)
    flat = [x.flatten(0, 1) for x in gx]
    inputs = [dbuf[T][:-1], *inbuf]
    for j, (m, key) in enumerate(((T, 0), (V, 1), (A_TOP, 2), (A_BOTTOM, 4))):
        if needs[key]:
            grad_w[key] = flat[m].t() @ inputs[j].flatten(0, 1)
    if w.w_va is not None and needs[3]:
        grad_z = flat[A_TOP] @ w.w_at[:, w.w_at.shape[1] - w.w_va.shape[0] :]
        grad_w[3] = grad_z.t() @ dbuf[V][1:].flatten(0, 1)
    gy1_flat, gout_flat = gy1.flatten(0, 1), gout.flatten(0, 1)
    if needs[5]:
        grad_w[5] = gy1_flat.t() @ dbuf[A_BOTTOM][1:].flatten(0, 1)
    if needs[6]:
        grad_w[6] = gy1_flat.sum(0)
    if needs[7]:
        grad_w[7] = gout_flat.t() @ y1.flatten(0, 1)
    if needs[8]:
        grad_w[8] = gout_flat.sum(0)
    return grad_w


def unpack_inputs(
    args: tuple[Tensor, ...],
) -> tuple[list[Tensor], list[Tensor], list[Tensor], Tensor, Tensor, FusedWeights]:
    """The flat autograd inputs of either backend: priors p, initial states h and d per module, a0, q0, weights."""
    return list(args[0:4]), list(args[4:8]), list(args[8:12]), args[12], args[13], FusedWeights(*args[14:])


def pack_outputs(
    meta: Meta, dbuf: list[Tensor], out: Tensor, abuf: Tensor, y1: Tensor, h_final: tuple[Tensor, ...] | list[Tensor]
) -> tuple[Tensor, ...]:
    """Either backend's forward outputs: d per module over the steps, q_hat, the action buffer, y1, final states."""
    q_hat = out[..., : meta.proprio_dim].contiguous()
    return (*(buf[1:] for buf in dbuf), q_hat, abuf, y1, *h_final)


def python_forward(meta: Meta, *args: Tensor) -> tuple[tuple[Tensor, ...], tuple[Tensor, ...]]:
    """The Python loops' forward: the outputs (`pack_outputs`) and the buffers its backward reads, each with the
    batch on dim 1."""
    p, h, d, a0, q0, w = unpack_inputs(args)
    (dbuf, gbuf, inbuf, y1, out, abuf, index), h_final = _forward(meta, p, h, d, a0, q0, w)
    return pack_outputs(meta, dbuf, out, abuf, y1, h_final), (*dbuf, *gbuf, *inbuf[1:], y1, out, abuf, index)


def python_backward(
    meta: Meta, buffers: tuple[Tensor, ...], w: FusedWeights, grads: tuple[Tensor | None, ...],
    needs_w: tuple[bool, ...],
) -> tuple[Tensor | None, ...]:
    """The Python loops' backward: the gradients of `unpack_inputs`' flat inputs from those of the outputs."""
    dbuf, gbuf, inbuf = buffers[0:4], buffers[4:8], (None, *buffers[8:11])
    y1, out, abuf, index = buffers[11:15]
    g_d, g_q, g_a, g_y1, g_h = grads[0:4], grads[4], grads[5], grads[6], grads[7:11]
    steps, batch = abuf.shape[:2]
    nq, k, na = meta.proprio_dim, meta.num_mixtures, meta.action_dim
    dims = [buf.shape[-1] for buf in dbuf]
    # Batched derivative factors: d/dh tanh(h) = 1 - d^2, d/dpre [h] = 1/tau (1 - g^2), ReLU mask, and
    # d a / d means = one-hot(argmax) (1 - a^2) for the mode's tanh mean.
    dd = [1 - buf[1:].square() for buf in dbuf]
    dg = [(alpha * (1 - buf.square())).unbind(0) for alpha, buf in zip(meta.alpha, gbuf, strict=True)]
    relu_mask = (y1 > 0).to(y1.dtype).unbind(0)
    one_hot = abuf.new_zeros((steps, batch, k, na)).scatter_(2, index, 1.0)
    da = (one_hot * (1 - abuf.square()).unsqueeze(2)).unbind(0)
    # External gradients on d^l enter h^l as ext (1 - d^2), added with the decayed carry (Eqs. 3-4).
    ext_h = [None if g is None else (g * x).unbind(0) for g, x in zip(g_d, dd, strict=True)]
    dd = [x.unbind(0) for x in dd]
    gx_buf = [buf.new_empty(buf.shape) for buf in gbuf]  # gradient of each pre-activation
    gout = out.new_zeros(out.shape)
    gy1 = y1.new_empty(y1.shape)
    gx, gy1_s = [b.unbind(0) for b in gx_buf], gy1.unbind(0)
    gout_s, gout_q = gout.unbind(0), gout[..., :nq].unbind(0)
    gout_means = gout[..., nq + k :].unflatten(-1, (k, na)).unbind(0)
    ext_q = None if g_q is None else g_q.unbind(0)
    ext_a = None if g_a is None else g_a.unbind(0)
    ext_y1 = None if g_y1 is None else g_y1.unbind(0)
    decay = [1.0 - alpha for alpha in meta.alpha]
    gh = [abuf.new_zeros((batch, n)) if g is None else g.clone() for g, n in zip(g_h, dims, strict=True)]
    for m in range(4):
        if ext_h[m] is not None:
            gh[m] = gh[m] + ext_h[m][-1]
    d_t_, d_v_, d_at_, d_ab_ = dims
    z_start = d_at_ + d_t_
    # Input gradients of each module's matmul, written by step i into slot i % 2 and read, as the carry to
    # step i - 1, from there: the gradients reaching d^l_{t-1} (the carry), d^T_t, z_t, a_{t-1}, q_{t-1} are
    # fixed column views of the two slots, so the loop splits nothing. Zeros: nothing reaches step T - 1.
    weights = [w.w_t, w.w_v, w.w_at, w.w_ab]
    slots = [abuf.new_zeros((2, batch, x.shape[1])) for x in weights]
    gin = [x.unbind(0) for x in slots]
    # Per slot, as (slot 0, slot 1) pairs of views.
    carry = [slots[m][..., :n].unbind(0) for m, n in enumerate(dims)]  # gradient reaching d^l_{t-1} from step t
    gd_at = slots[A_BOTTOM][..., d_ab_:].unbind(0)
    gd_t_at, gz = slots[A_TOP][..., d_at_:z_start].unbind(0), slots[A_TOP][..., z_start:].unbind(0)
    gd_t_v = slots[V][..., d_v_ : d_v_ + d_t_].unbind(0)
    if meta.efference:
        carry_a, carry_q = slots[V][..., d_v_ + d_t_ : d_v_ + d_t_ + na], slots[V][..., d_v_ + d_t_ + na :]
    else:
        carry_a, carry_q = abuf.new_zeros((2, batch, na)), abuf.new_zeros((2, batch, nq))
    carry_a3 = carry_a.unsqueeze(2).unbind(0)  # (batch, 1, a): broadcast over the mixture components
    carry_a, carry_q = carry_a.unbind(0), carry_q.unbind(0)

    def module(m: int, i: int, gd: Tensor) -> None:
        """Leaky-integrator backward (Eqs. 3-4) of module m at step i; its input gradient goes to slot i % 2."""
        gh_i = torch.addcmul(gh[m], gd, dd[m][i])
        torch.mul(gh_i, dg[m][i], out=gx[m][i])
        # Carry to step i - 1: (1 - 1/tau) gh_i, plus that step's external term.
        no_ext = ext_h[m] is None or i == 0
        gh[m] = torch.mul(gh_i, decay[m]) if no_ext else torch.add(ext_h[m][i - 1], gh_i, alpha=decay[m])
        torch.mm(gx[m][i], weights[m], out=gin[m][i & 1])

    for i in reversed(range(steps)):
        now, c = i & 1, 1 - (i & 1)  # slot step i writes, slot holding step i + 1's input gradients
        # Heads: q_hat and the selected component's tanh mean (the argmax carries no gradient).
        if ext_q is None:
            gout_q[i].copy_(carry_q[c])
        else:
            torch.add(carry_q[c], ext_q[i], out=gout_q[i])
        if ext_a is not None:
            torch.mul(da[i], (carry_a[c] + ext_a[i]).unsqueeze(1), out=gout_means[i])
        elif meta.efference:
            torch.mul(da[i], carry_a3[c], out=gout_means[i])
        if ext_y1 is None:
            torch.mm(gout_s[i], w.w2, out=gy1_s[i])
        else:
            torch.addmm(ext_y1[i], gout_s[i], w.w2, out=gy1_s[i])
        gy1_s[i].mul_(relu_mask[i])
        module(A_BOTTOM, i, torch.addmm(carry[A_BOTTOM][c], gy1_s[i], w.w1))
        module(A_TOP, i, carry[A_TOP][c] + gd_at[now])
        module(V, i, torch.addmm(carry[V][c], gz[now], w.w_va) if w.w_va is not None else carry[V][c])
        module(T, i, torch.add(carry[T][c], gd_t_at[now]).add_(gd_t_v[now]))
    carry, carry_a, carry_q = [x[0] for x in carry], carry_a[0], carry_q[0]  # step 0 wrote slot 0

    grad_w = weight_gradients(needs_w, w, gx_buf, dbuf, inbuf[1:], y1, gy1, gout)
    grad_a0, grad_q0 = (carry_a, carry_q) if meta.efference else (None, None)
    return (*gx_buf, *gh, *carry, grad_a0, grad_q0, *grad_w)


class Kernels(NamedTuple):
    """One backend's loops: `forward(meta, *inputs)` -> (outputs, buffers with the batch on dim 1) and
    `backward(meta, buffers, weights, output gradients, which weights need one)` -> the inputs' gradients."""

    forward: Callable[..., tuple[tuple[Tensor, ...], tuple[Tensor, ...]]]
    backward: Callable[..., tuple[Tensor | None, ...]]


PYTHON_KERNELS = Kernels(python_forward, python_backward)
WEIGHTS_AT = 14  # index of the first FusedWeights field among the flat inputs (`unpack_inputs`)
Y1_AT = 6  # index of the heads' hidden layer y1 among the outputs (`pack_outputs`)


class Recurrence(torch.autograd.Function):
    """Eqs. 3-6 over a sequence as one autograd node, on either backend's `Kernels`."""

    @staticmethod
    def forward(ctx, kernels: Kernels, meta: Meta, *args: Tensor):
        outs, buffers = kernels.forward(meta, *args)
        ctx.kernels, ctx.meta, ctx.buffers = kernels, meta, len(buffers)
        ctx.save_for_backward(*buffers, *args[WEIGHTS_AT:])
        return outs

    @staticmethod
    def backward(ctx, *grads: Tensor | None):
        buffers, w, needs_w = saved_for_backward(ctx)
        return (None, None, *ctx.kernels.backward(ctx.meta, buffers, w, grads, needs_w))


def saved_for_backward(ctx) -> tuple[tuple[Tensor, ...], FusedWeights, tuple[bool, ...]]:
    """What `Recurrence.forward` saved: the kernels' buffers, the weights, and which weights need a gradient."""
    saved = ctx.saved_tensors
    weights_at = 2 + WEIGHTS_AT  # apply's arguments: kernels, meta, then the flat inputs
    needs_w = ctx.needs_input_grad[weights_at : weights_at + len(FusedWeights._fields)]
    return saved[: ctx.buffers], FusedWeights(*saved[ctx.buffers :]), needs_w


class SharedActingChain(torch.autograd.Function):
    """Eqs. 3-6 run once for two chains of equal values that differ in their gradients only.

    The posterior chain (priors `p`, every output) carries every term of Eq. 10 but the action term; the action
    term's chain (priors `p_act`, equal to `p` in value: the same posteriors detached) carries the action term, whose
    gradient then reaches the network and not the posteriors (`PredVLAConfig.posteriors_fit_actions=False`). The
    values of both chains are the forward's, computed once; its only extra output is a copy of the heads' hidden layer,
    the action term's input. Every gradient is that of two separate rollouts (the shared initial states and weights
    get their sum), from two backward passes over the one forward's buffers.
    """

    @staticmethod
    def forward(ctx, kernels: Kernels, meta: Meta, *args: Tensor):
        # The last four arguments are p_act: the same values as p, only a gradient goes there.
        outs = Recurrence.forward(ctx, kernels, meta, *args[:-4])
        return (*outs, outs[Y1_AT].clone())

    @staticmethod
    def backward(ctx, *grads: Tensor | None):
        (buffers, w, needs_w), grads, g_act = saved_for_backward(ctx), grads[:-1], grads[-1]
        if g_act is None:  # no action term: the posterior chain alone
            return (None, None, *ctx.kernels.backward(ctx.meta, buffers, w, grads, needs_w), None, None, None, None)
        # The backward is linear in the outputs' gradients: one pass with both chains' together gives every
        # gradient but the split of the priors' between p and p_act; a second pass with the action chain's alone
        # (no weight gradient) gives p_act's, and p's is the rest.
        both = list(grads)
        both[Y1_AT] = g_act if grads[Y1_AT] is None else grads[Y1_AT] + g_act
        out = ctx.kernels.backward(ctx.meta, buffers, w, tuple(both), needs_w)
        action_only = tuple(g_act if i == Y1_AT else None for i in range(len(grads)))
        g_p_act = ctx.kernels.backward(ctx.meta, buffers, w, action_only, (False,) * len(needs_w))[0:4]
        g_p = [total - act for total, act in zip(out[0:4], g_p_act, strict=True)]
        return (None, None, *g_p, *out[4:], *g_p_act)


def shared_acting_chain(
    kernels: Kernels, meta: Meta, p: list[Tensor], p_act: list[Tensor], h: tuple[Tensor, ...],
    d: tuple[Tensor, ...], a: Tensor, q: Tensor, w: FusedWeights,
) -> tuple[list[Tensor], Tensor, Tensor, Tensor, tuple[Tensor, ...], Tensor]:
    """`recurrence`'s outputs for priors `p`, and the heads' hidden layer of the action term's chain, whose gradient
    goes to `p_act` (equal to `p` in value) instead of `p` (`SharedActingChain`)."""
    outs = SharedActingChain.apply(kernels, meta, *p, *h, *d, a, q, *w, *p_act)
    return list(outs[0:4]), outs[4], outs[5], outs[6], tuple(outs[7:11]), outs[11]


def recurrence(
    meta: Meta, p: list[Tensor], h: tuple[Tensor, ...], d: tuple[Tensor, ...], a: Tensor, q: Tensor, w: FusedWeights
) -> tuple[list[Tensor], Tensor, Tensor, Tensor, tuple[Tensor, ...]]:
    """Run Eqs. 3-6 over p's steps.

    Returns, time-major, d^l of every module, q_hat, a_hat and the heads' hidden layer [q | action] (after
    ReLU), and the final h^l.
    """
    outs = Recurrence.apply(PYTHON_KERNELS, meta, *p, *h, *d, a, q, *w)
    return list(outs[0:4]), outs[4], outs[5], outs[6], tuple(outs[7:11])
