"""The recurrent cells and dense layers, single step, unbatched (pure JAX).

Parameters are plain dicts of arrays in PyTorch's layout (so the published models'
shapes and counts carry over, and the C export reads them as they are):

- linear: `w` (out, in), `b` (out,): y = w x + b.
- Elman RNN (PyTorch `nn.RNN`, tanh): `w_ih` (h, in), `w_hh` (h, h), `b_ih`, `b_hh` (h,):
  h' = tanh(w_ih x + b_ih + w_hh h + b_hh).
- GRU (PyTorch `nn.GRU`): `w_ih` (3h, in), `w_hh` (3h, h), `b_ih`, `b_hh` (3h,), gates
  stacked in the order reset r, update z, candidate n:
  r = σ(W_ir x + b_ir + W_hr h + b_hr), z = σ(W_iz x + b_iz + W_hz h + b_hz),
  n = tanh(W_in x + b_in + r ⊙ (W_hn h + b_hn)), h' = (1 − z) ⊙ n + z ⊙ h.

Initialisation as PyTorch's: every weight and bias uniform in ±1/√fan (the hidden size
for the recurrent cells, the input size for a linear layer).
"""

import jax
import jax.numpy as jnp


def calc_linear(params: dict, x):
    return params["w"] @ x + params["b"]


def calc_rnn_step(params: dict, h, x):
    """One step of the tanh Elman cell: the new hidden state (h,)."""
    return jnp.tanh(params["w_ih"] @ x + params["b_ih"] + params["w_hh"] @ h + params["b_hh"])


def calc_gru_step(params: dict, h, x):
    """One step of the GRU cell: the new hidden state (h,)."""
    gi = params["w_ih"] @ x + params["b_ih"]
    gh = params["w_hh"] @ h + params["b_hh"]
    i_r, i_z, i_n = jnp.split(gi, 3)
    h_r, h_z, h_n = jnp.split(gh, 3)
    r = jax.nn.sigmoid(i_r + h_r)
    z = jax.nn.sigmoid(i_z + h_z)
    n = jnp.tanh(i_n + r * h_n)
    return (1.0 - z) * n + z * h


def _uniform(key, shape, bound, dtype):
    return jax.random.uniform(key, shape, dtype, -bound, bound)


def init_linear(key, num_inputs: int, num_outputs: int, dtype=jnp.float32) -> dict:
    k_w, k_b = jax.random.split(key)
    bound = 1.0 / num_inputs**0.5
    return {"w": _uniform(k_w, (num_outputs, num_inputs), bound, dtype), "b": _uniform(k_b, (num_outputs,), bound, dtype)}


def init_recurrent(key, num_inputs: int, hidden: int, gates: int, dtype=jnp.float32) -> dict:
    """An RNN (gates = 1) or GRU (gates = 3) layer's parameters."""
    keys = jax.random.split(key, 4)
    bound = 1.0 / hidden**0.5
    shapes = {"w_ih": (gates * hidden, num_inputs), "w_hh": (gates * hidden, hidden), "b_ih": (gates * hidden,), "b_hh": (gates * hidden,)}
    return {name: _uniform(k, shape, bound, dtype) for k, (name, shape) in zip(keys, shapes.items())}
