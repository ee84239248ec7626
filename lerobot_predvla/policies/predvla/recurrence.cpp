
#include <torch/extension.h>
#include <dlfcn.h>
#include <cmath>
#include <optional>
#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace {

using at::Tensor;
constexpr int T = 0, V = 1, A_TOP = 2, A_BOTTOM = 3;

// tanh over n contiguous values: glibc's AVX2 vector kernels (libmvec >= 2.35), resolved once, else std::tanh.
#if defined(__x86_64__)
using TanhF8 = __m256 (*)(__m256);
using TanhD4 = __m256d (*)(__m256d);
struct VectorTanh {
  TanhF8 f8 = nullptr;
  TanhD4 d4 = nullptr;
  VectorTanh() {
    if (!__builtin_cpu_supports("avx2")) return;
    void* lib = dlopen("libmvec.so.1", RTLD_NOW);
    if (lib == nullptr) return;
    f8 = reinterpret_cast<TanhF8>(dlsym(lib, "_ZGVdN8v_tanhf"));
    d4 = reinterpret_cast<TanhD4>(dlsym(lib, "_ZGVdN4v_tanh"));
    if (f8 == nullptr || d4 == nullptr) f8 = nullptr, d4 = nullptr;
  }
};
const VectorTanh vector_tanh;

__attribute__((target("avx2"))) int64_t tanh_avx2(const float* x, float* y, int64_t n) {
  int64_t j = 0;
  for (; j + 8 <= n; j += 8) _mm256_storeu_ps(y + j, vector_tanh.f8(_mm256_loadu_ps(x + j)));
  return j;
}
__attribute__((target("avx2"))) int64_t tanh_avx2(const double* x, double* y, int64_t n) {
  int64_t j = 0;
  for (; j + 4 <= n; j += 4) _mm256_storeu_pd(y + j, vector_tanh.d4(_mm256_loadu_pd(x + j)));
  return j;
}
#endif

template <typename S>
void tanh_into(const S* x, S* y, int64_t n) {
  int64_t j = 0;
#if defined(__x86_64__)
  if (vector_tanh.f8 != nullptr) j = tanh_avx2(x, y, n);
#endif
  for (; j < n; ++j) y[j] = std::tanh(x[j]);
}

std::string tanh_kernel() {
#if defined(__x86_64__)
  if (vector_tanh.f8 != nullptr) return "glibc libmvec AVX2";
#endif
  return "std::tanh (scalar)";
}

template <typename S>
S* row(const Tensor& buf, int64_t i) {  // step i of a contiguous (steps, batch, n) buffer
  return buf.data_ptr<S>() + i * buf.stride(0);
}

template <typename S>
const S* maybe_row(const std::optional<Tensor>& buf, int64_t i) {
  return buf.has_value() ? row<S>(*buf, i) : nullptr;
}

// Eqs. 3-4 on the pre-activation g = P + W x of one module (batch x n values, in place):
// g <- tanh(g), h <- (1 - 1/tau) h + 1/tau g (torch.lerp's formula), d <- tanh(h).
template <typename S>
void leaky(S* g, S* h, S* d, int64_t size, S alpha) {
  tanh_into(g, g, size);
  if (std::abs(alpha) < S(0.5)) {
    for (int64_t j = 0; j < size; ++j) h[j] = h[j] + alpha * (g[j] - h[j]);
  } else {
    for (int64_t j = 0; j < size; ++j) h[j] = g[j] - (g[j] - h[j]) * (S(1) - alpha);
  }
  tanh_into(h, d, size);
}

// One input of a module's matmul: n columns per batch row, rows `stride` values apart.
template <typename S>
struct Part {
  const S* src;
  int64_t n;
  int64_t stride;
};

// Copies the parts side by side into dst (batch rows of the parts' total width): the concatenated input.
template <typename S>
void concat(S* dst, int64_t batch, std::initializer_list<Part<S>> parts) {
  for (int64_t b = 0; b < batch; ++b) {
    for (const auto& part : parts) dst = std::copy_n(part.src + b * part.stride, part.n, dst);
  }
}

template <typename S>
std::vector<Tensor> forward_impl(
    const std::vector<double>& alpha, bool efference, int64_t k, int64_t na, int64_t nq,
    const std::vector<Tensor>& p, const std::vector<Tensor>& h0, const std::vector<Tensor>& d0, const Tensor& a0,
    const Tensor& q0, const std::vector<Tensor>& wt, const std::optional<Tensor>& w_va_t, const Tensor& w1_t,
    const Tensor& b1, const Tensor& w2_t, const Tensor& b2) {
  const int64_t steps = p[T].size(0), batch = p[T].size(1), nout = w2_t.size(1);
  const auto opts = a0.options();
  std::vector<Tensor> dbuf, gbuf, inbuf, h;  // D^l: d^l_0..d^l_T; G^l = tanh(pre-activation); IN^l = matmul inputs
  std::vector<int64_t> n;
  for (int m = 0; m < 4; ++m) {
    n.push_back(d0[m].size(1));
    dbuf.push_back(at::empty({steps + 1, batch, n[m]}, opts));
    dbuf[m][0].copy_(d0[m]);
    gbuf.push_back(at::empty({steps, batch, n[m]}, opts));
    h.push_back(h0[m].contiguous().clone());
    inbuf.push_back(m == T ? Tensor() : at::empty({steps, batch, wt[m].size(0)}, opts));
  }
  Tensor y1 = at::empty({steps, batch, w1_t.size(1)}, opts), out = at::empty({steps, batch, nout}, opts);
  Tensor abuf = at::empty({steps, batch, na}, opts), index = at::empty({steps, batch}, opts.dtype(at::kLong));
  const Tensor a_init = a0.contiguous(), q_init = q0.contiguous();
  const bool has_va = w_va_t.has_value();
  Tensor z = has_va ? at::empty({batch, w_va_t->size(1)}, opts) : Tensor();
  const int64_t nz = has_va ? z.size(1) : 0;
  auto sizes = [&](int m) { return batch * n[m]; };
  for (int64_t i = 0; i < steps; ++i) {
    const S* a_prev = i == 0 ? a_init.data_ptr<S>() : row<S>(abuf, i - 1);
    // q_{t-1}: the first nq columns of the previous step's heads output [q_hat | logits | means], or q_0.
    const Part<S> q_prev = i == 0 ? Part<S>{q_init.data_ptr<S>(), nq, nq} : Part<S>{row<S>(out, i - 1), nq, nout};
    // T (Eq. 4): h = (1 - 1/tau) h + 1/tau tanh(P + W_rec d_{t-1}), d = tanh(h).
    Tensor g = gbuf[T][i];
    at::addmm_out(g, p[T][i], dbuf[T][i], wt[T]);
    leaky(g.data_ptr<S>(), h[T].data_ptr<S>(), row<S>(dbuf[T], i + 1), sizes(T), S(alpha[T]));
    const S* d_t = row<S>(dbuf[T], i + 1);
    // V (Eqs. 3, 6): [W_rec | W_td | W_ba | W_bq] [d^V_{t-1}; d^T_t; a_{t-1}; q_{t-1}].
    if (efference) {
      concat<S>(row<S>(inbuf[V], i), batch, {{row<S>(dbuf[V], i), n[V], n[V]}, {d_t, n[T], n[T]},
                                             {a_prev, na, na}, q_prev});
    } else {
      concat<S>(row<S>(inbuf[V], i), batch, {{row<S>(dbuf[V], i), n[V], n[V]}, {d_t, n[T], n[T]}});
    }
    g = gbuf[V][i];
    at::addmm_out(g, p[V][i], inbuf[V][i], wt[V]);
    leaky(g.data_ptr<S>(), h[V].data_ptr<S>(), row<S>(dbuf[V], i + 1), sizes(V), S(alpha[V]));
    // A_top (Eqs. 3, 5): [W_rec | W_td | W_top] [d^At_{t-1}; d^T_t; z_t], z = W_VA d^V_t.
    if (has_va) {
      at::mm_out(z, dbuf[V][i + 1], *w_va_t);
      concat<S>(row<S>(inbuf[A_TOP], i), batch, {{row<S>(dbuf[A_TOP], i), n[A_TOP], n[A_TOP]},
                                                 {d_t, n[T], n[T]}, {z.data_ptr<S>(), nz, nz}});
    } else {
      concat<S>(row<S>(inbuf[A_TOP], i), batch, {{row<S>(dbuf[A_TOP], i), n[A_TOP], n[A_TOP]},
                                                 {d_t, n[T], n[T]}});
    }
    g = gbuf[A_TOP][i];
    at::addmm_out(g, p[A_TOP][i], inbuf[A_TOP][i], wt[A_TOP]);
    leaky(g.data_ptr<S>(), h[A_TOP].data_ptr<S>(), row<S>(dbuf[A_TOP], i + 1), sizes(A_TOP), S(alpha[A_TOP]));
    // A_bottom (Eq. 3).
    concat<S>(row<S>(inbuf[A_BOTTOM], i), batch, {{row<S>(dbuf[A_BOTTOM], i), n[A_BOTTOM], n[A_BOTTOM]},
                                                  {row<S>(dbuf[A_TOP], i + 1), n[A_TOP], n[A_TOP]}});
    g = gbuf[A_BOTTOM][i];
    at::addmm_out(g, p[A_BOTTOM][i], inbuf[A_BOTTOM][i], wt[A_BOTTOM]);
    leaky(g.data_ptr<S>(), h[A_BOTTOM].data_ptr<S>(), row<S>(dbuf[A_BOTTOM], i + 1), sizes(A_BOTTOM),
          S(alpha[A_BOTTOM]));
    // Heads: [q_hat | logits | means] = W2 ReLU(W1 d^Ab + b1) + b2; the executed action is the tanh mean of the
    // highest-weight component (the GMM mode, Section 3.2), fed back by Eq. 6.
    Tensor y1_i = y1[i], out_i = out[i];
    at::addmm_out(y1_i, b1, dbuf[A_BOTTOM][i + 1], w1_t);
    S* y = y1_i.data_ptr<S>();
    for (int64_t j = 0; j < y1_i.numel(); ++j) y[j] = y[j] < S(0) ? S(0) : y[j];  // relu_, NaN kept as ATen's
    at::addmm_out(out_i, b2, y1_i, w2_t);
    const S* o = out_i.data_ptr<S>();
    S* a = row<S>(abuf, i);
    int64_t* idx = index.data_ptr<int64_t>() + i * batch;
    for (int64_t b = 0; b < batch; ++b) {
      const S* logits = o + b * nout + nq;
      int64_t best = 0;  // torch.argmax: the first maximum, NaN counting as the largest
      for (int64_t c = 1; c < k; ++c) {
        if (!std::isnan(logits[best]) && (logits[c] > logits[best] || std::isnan(logits[c]))) best = c;
      }
      idx[b] = best;
      const S* mean = logits + k + best * na;
      for (int64_t j = 0; j < na; ++j) a[b * na + j] = std::tanh(mean[j]);
    }
  }
  std::vector<Tensor> result(dbuf);
  result.insert(result.end(), gbuf.begin(), gbuf.end());
  result.insert(result.end(), inbuf.begin() + 1, inbuf.end());
  result.insert(result.end(), {y1, out, abuf, index});
  result.insert(result.end(), h.begin(), h.end());
  return result;
}

template <typename S>
std::vector<Tensor> backward_impl(
    const std::vector<double>& alpha, bool efference, int64_t k, int64_t na, int64_t nq,
    const std::vector<Tensor>& dbuf, const std::vector<Tensor>& gbuf, const Tensor& y1, const Tensor& abuf,
    const Tensor& index, const std::vector<Tensor>& w, const std::optional<Tensor>& w_va, const Tensor& w1,
    const Tensor& w2, const std::vector<std::optional<Tensor>>& g_d, const std::optional<Tensor>& g_q,
    const std::optional<Tensor>& g_a, const std::optional<Tensor>& g_y1,
    const std::vector<std::optional<Tensor>>& g_h) {
  const int64_t steps = abuf.size(0), batch = abuf.size(1), nout = w2.size(0);
  const auto opts = abuf.options();
  std::vector<int64_t> n, width;
  std::vector<Tensor> gx, gh, slots, scratch;
  std::vector<std::optional<Tensor>> ext_d;
  for (int m = 0; m < 4; ++m) {
    n.push_back(dbuf[m].size(2));
    width.push_back(w[m].size(1));
    gx.push_back(at::empty({steps, batch, n[m]}, opts));  // gradient of each pre-activation
    gh.push_back(g_h[m].has_value() ? g_h[m]->contiguous().clone() : at::zeros({batch, n[m]}, opts));
    // Input gradients of module m's matmul: step i writes slot i % 2, step i - 1 reads it as its carry.
    slots.push_back(at::zeros({2, batch, width[m]}, opts));
    scratch.push_back(at::empty({batch, n[m]}, opts));  // gradient reaching d^l_t
    ext_d.push_back(g_d[m].has_value() ? std::optional<Tensor>(g_d[m]->contiguous()) : std::nullopt);
  }
  const std::optional<Tensor> ext_q = g_q.has_value() ? std::optional<Tensor>(g_q->contiguous()) : std::nullopt;
  const std::optional<Tensor> ext_a = g_a.has_value() ? std::optional<Tensor>(g_a->contiguous()) : std::nullopt;
  Tensor gout = at::zeros({steps, batch, nout}, opts), gy1 = at::empty(y1.sizes(), opts);
  const bool has_va = w_va.has_value();
  const int64_t z_start = n[A_TOP] + n[T], efference_start = n[V] + n[T];
  // External gradients on d^l enter h^l as ext (1 - d^2), added to the decayed carry (Eqs. 3-4).
  for (int m = 0; m < 4; ++m) {
    if (!ext_d[m].has_value()) continue;
    const S* e = row<S>(*ext_d[m], steps - 1);
    const S* d = row<S>(dbuf[m], steps);
    S* out = gh[m].data_ptr<S>();
    for (int64_t j = 0; j < batch * n[m]; ++j) out[j] = out[j] + e[j] * (S(1) - d[j] * d[j]);
  }
  // Column j of slot s of module m's input gradient, row b.
  auto slot = [&](int m, int s, int64_t b, int64_t j) {
    return slots[m].data_ptr<S>() + (s * batch + b) * width[m] + j;
  };

  // Leaky-integrator backward (Eqs. 3-4) of module m at step i, given the gradient gd reaching d^m_t; writes the
  // pre-activation gradient, carries (1 - 1/tau) gh (+ the external term of step i - 1) and forms the input
  // gradient W^T gx into slot i % 2.
  auto module = [&](int m, int64_t i, const S* gd) {
    const S* d = row<S>(dbuf[m], i + 1);
    const S* d_prev = row<S>(dbuf[m], i);
    const S* g = row<S>(gbuf[m], i);
    const S* e = (ext_d[m].has_value() && i > 0) ? row<S>(*ext_d[m], i - 1) : nullptr;
    S* x = row<S>(gx[m], i);
    S* carry = gh[m].data_ptr<S>();
    const S a = S(alpha[m]), decay = S(1.0 - alpha[m]);
    for (int64_t j = 0; j < batch * n[m]; ++j) {
      const S gh_i = carry[j] + gd[j] * (S(1) - d[j] * d[j]);
      x[j] = gh_i * (a * (S(1) - g[j] * g[j]));
      carry[j] = e == nullptr ? gh_i * decay : e[j] * (S(1) - d_prev[j] * d_prev[j]) + decay * gh_i;
    }
    Tensor gin = slots[m][i & 1];
    at::mm_out(gin, gx[m][i], w[m]);
  };
  // The carry of module m (gradient reaching d^m_{t-1} from step t) as a (batch, n) view of slot s.
  auto carry_view = [&](int m, int s) { return slots[m][s].narrow(1, 0, n[m]); };

  for (int64_t i = steps - 1; i >= 0; --i) {
    const int now = i & 1, c = 1 - now;  // slot step i writes; slot holding step i + 1's input gradients
    // Heads: q_hat and the selected component's tanh mean (the argmax carries no gradient).
    S* go = row<S>(gout, i);
    const S* eq = maybe_row<S>(ext_q, i);
    const S* ea = maybe_row<S>(ext_a, i);
    const S* a = row<S>(abuf, i);
    const int64_t* idx = index.data_ptr<int64_t>() + i * batch;
    for (int64_t b = 0; b < batch; ++b) {
      for (int64_t j = 0; j < nq; ++j) {
        const S carry_q = efference ? *slot(V, c, b, efference_start + na + j) : S(0);
        go[b * nout + j] = eq == nullptr ? carry_q : carry_q + eq[b * nq + j];
      }
      if (ea == nullptr && !efference) continue;
      S* gm = go + b * nout + nq + k + idx[b] * na;
      for (int64_t j = 0; j < na; ++j) {
        const S carry_a = efference ? *slot(V, c, b, efference_start + j) : S(0);
        const S av = a[b * na + j];
        gm[j] = (S(1) - av * av) * (ea == nullptr ? carry_a : carry_a + ea[b * na + j]);
      }
    }
    Tensor gy1_i = gy1[i];
    if (g_y1.has_value()) {
      at::addmm_out(gy1_i, (*g_y1)[i], gout[i], w2);
    } else {
      at::mm_out(gy1_i, gout[i], w2);
    }
    S* gy = gy1_i.data_ptr<S>();
    const S* y = row<S>(y1, i);
    for (int64_t j = 0; j < gy1_i.numel(); ++j) gy[j] = gy[j] * (y[j] > S(0) ? S(1) : S(0));  // ReLU mask
    // A_bottom: from the heads' first layer and from step t + 1.
    at::addmm_out(scratch[A_BOTTOM], carry_view(A_BOTTOM, c), gy1_i, w1);
    module(A_BOTTOM, i, scratch[A_BOTTOM].data_ptr<S>());
    // A_top: from step t + 1 and from A_bottom's top-down input.
    S* gd = scratch[A_TOP].data_ptr<S>();
    for (int64_t b = 0; b < batch; ++b) {
      for (int64_t j = 0; j < n[A_TOP]; ++j) {
        gd[b * n[A_TOP] + j] = *slot(A_TOP, c, b, j) + *slot(A_BOTTOM, now, b, n[A_BOTTOM] + j);
      }
    }
    module(A_TOP, i, gd);
    // V: from step t + 1 and, through the bottleneck z = W_VA d^V (Eq. 5), from A_top.
    gd = scratch[V].data_ptr<S>();
    if (has_va) {
      at::addmm_out(scratch[V], carry_view(V, c), slots[A_TOP][now].narrow(1, z_start, width[A_TOP] - z_start),
                    *w_va);
    } else {
      for (int64_t b = 0; b < batch; ++b) std::copy_n(slot(V, c, b, 0), n[V], gd + b * n[V]);
    }
    module(V, i, gd);
    // T: from step t + 1 and the top-down inputs of A_top and V.
    gd = scratch[T].data_ptr<S>();
    for (int64_t b = 0; b < batch; ++b) {
      for (int64_t j = 0; j < n[T]; ++j) {
        gd[b * n[T] + j] = (*slot(T, c, b, j) + *slot(A_TOP, now, b, n[A_TOP] + j)) + *slot(V, now, b, n[V] + j);
      }
    }
    module(T, i, gd);
  }
  // Step 0 wrote slot 0: gradients reaching d^l_0, a_0 and q_0.
  std::vector<Tensor> result(gx);
  result.insert(result.end(), {gout, gy1});
  result.insert(result.end(), gh.begin(), gh.end());
  for (int m = 0; m < 4; ++m) result.push_back(carry_view(m, 0));
  if (efference) {
    result.push_back(slots[V][0].narrow(1, efference_start, na));
    result.push_back(slots[V][0].narrow(1, efference_start + na, nq));
  }
  return result;
}

void check(const Tensor& reference, const std::vector<Tensor>& tensors) {
  for (const auto& x : tensors) {
    TORCH_CHECK(!x.defined() || (x.device().is_cpu() && x.scalar_type() == reference.scalar_type()),
                "recurrence_backend='cpp': every tensor must be on the CPU with the same dtype");
  }
}

}  // namespace

std::vector<Tensor> forward(
    std::vector<double> alpha, bool efference, int64_t k, int64_t na, int64_t nq, std::vector<Tensor> p,
    std::vector<Tensor> h0, std::vector<Tensor> d0, Tensor a0, Tensor q0, std::vector<Tensor> wt,
    std::optional<Tensor> w_va_t, Tensor w1_t, Tensor b1, Tensor w2_t, Tensor b2) {
  check(a0, p); check(a0, h0); check(a0, d0); check(a0, wt);
  check(a0, {q0, w1_t, b1, w2_t, b2, w_va_t.value_or(Tensor())});
  const at::AutoDispatchBelowADInplaceOrView below_autograd;  // autograd is the caller's (_CppRecurrence)
  std::vector<Tensor> result;
  AT_DISPATCH_FLOATING_TYPES(a0.scalar_type(), "predvla_recurrence_forward", [&] {
    result = forward_impl<scalar_t>(alpha, efference, k, na, nq, p, h0, d0, a0, q0, wt, w_va_t, w1_t, b1, w2_t, b2);
  });
  return result;
}

std::vector<Tensor> backward(
    std::vector<double> alpha, bool efference, int64_t k, int64_t na, int64_t nq, std::vector<Tensor> dbuf,
    std::vector<Tensor> gbuf, Tensor y1, Tensor abuf, Tensor index, std::vector<Tensor> w,
    std::optional<Tensor> w_va, Tensor w1, Tensor w2, std::vector<std::optional<Tensor>> g_d,
    std::optional<Tensor> g_q, std::optional<Tensor> g_a, std::optional<Tensor> g_y1,
    std::vector<std::optional<Tensor>> g_h) {
  const at::AutoDispatchBelowADInplaceOrView below_autograd;
  std::vector<Tensor> result;
  AT_DISPATCH_FLOATING_TYPES(abuf.scalar_type(), "predvla_recurrence_backward", [&] {
    result = backward_impl<scalar_t>(alpha, efference, k, na, nq, dbuf, gbuf, y1, abuf, index, w, w_va, w1, w2,
                                     g_d, g_q, g_a, g_y1, g_h);
  });
  return result;
}
