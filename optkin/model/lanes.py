"""SX Functions compiled to C that evaluates eight points at once (SIMD lanes).

CasADi's generated C evaluates one point per call, each operation on one double; a map
over many points calls it once per point. Where the same SX graph is evaluated for many
points at a time (the homotopy's paths), :func:`kernel` writes it instead with GCC's vector
extensions: every value of the graph is a vector of :data:`LANES` doubles, one per point,
and every operation acts on all of them (AVX-512 on a machine that has it, pairs of AVX2
or SSE2 operations otherwise). Branches become selects (both sides evaluated): CasADi's
``if_else`` and the logical operations give 1.0 / 0.0 as they do in CasADi's code,
``fmin``/``fmax`` keep C's NaN rule (the other operand), comparisons with NaN are false.

:func:`chunk_source` puts such kernels behind CasADi's external-function interface
(``name``, ``name_n_in``, ``name_sparsity_in``, ...), so that the library is built,
cached, verified and loaded like every other (:func:`optkin.model.compiled.start_library`
with a ``source``). Measured on a 6-6 platform's tracker (19.7k operations a step after
common subexpressions are merged): 0.65 us a path-step with AVX-512 in a fast spell of
this machine; the whole homotopy 3.6x faster than through CasADi's compiled chunk of the
same operations in one run (6.4 against 23 ms). Compiled without contracting
multiplications and additions (``-ffp-contract=off``): the lanes give CasADi's numbers to
the bit.
"""

from __future__ import annotations

import hashlib
import os
import platform
from collections.abc import Sequence
from typing import Any

import casadi as ca

__all__ = ["LANES", "kernel", "single_sx", "chunk_source", "function_source",
           "lanes_function", "cpu_key", "FLAGS"]

#: Points per vector (doubles in 64 bytes).
LANES = 8

#: Most operations a lanes library is written for (a 6-6 platform's tracker: 36.6k).
MAX_OPS = 80_000

#: Compiler flags of a lanes library: the vectors of the machine that builds it (the cache
#: key holds :func:`cpu_key`, so another machine sharing the cache builds its own).
FLAGS = ("-O1", "-march=native", "-ffp-contract=off", "-shared", "-fPIC")

_HEADER = r"""/* optkin lanes: generated, do not edit */
#include <string.h>
#include <math.h>
typedef double vd __attribute__((vector_size(64)));
typedef long long vl __attribute__((vector_size(64)));
#define LANES 8
#define casadi_int long long int
#define casadi_real double
static inline vd sel(vl m, vd a, vd b) { return (vd)((m & (vl)a) | (~m & (vl)b)); }
static inline vd vsqrt(vd a) {
  vd r; for (int j = 0; j < LANES; ++j) r[j] = __builtin_sqrt(a[j]); return r; }
static inline vd vfabs(vd a) { vl m = (vl){0} + 0x7fffffffffffffffLL; return (vd)((vl)a & m); }
static inline vd ld(const double* p) { vd r; memcpy(&r, p, sizeof r); return r; }
static inline void st(double* p, vd v) { memcpy(p, &v, sizeof v); }
"""

_OP_NAMES = {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}


def _literal(c: float) -> str:
    if c != c:
        return "NAN"
    if c in (float("inf"), -float("inf")):
        return "INFINITY" if c > 0 else "(-INFINITY)"
    return c.hex()


def kernel(f: ca.Function, name: str, shared: Sequence[int] = ()) -> str:
    """C of ``static void name(const double* const* in, double* const* out)`` evaluating
    the SX Function ``f`` at :data:`LANES` points: input ``i`` (not in ``shared``) holds
    its nonzero ``j`` of lane ``k`` at ``in[i][j * LANES + k]``, as does every output; an
    input in ``shared`` is the same for every lane (``in[i][j]``).

    Raises
    ------
    ValueError
        An operation this writer does not know (the caller keeps CasADi's code).
    """
    if not f.is_a("SXFunction"):
        raise ValueError(f"lanes: {f.name()} is not an SX Function")
    shared = set(shared)
    lines = [f"static void {name}(const double* const* in, double* const* out) {{",
             "  const vd ONE = (vd){0} + 1.0, ZERO = (vd){0};"]
    nw = f.sz_w()
    if nw:
        lines.append("  vd " + ", ".join(f"w{i}" for i in range(nw)) + ";")

    def b(e: str) -> str:
        return f"sel({e}, ONE, ZERO)"

    const: dict[int, float] = {}
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        i, o = f.instruction_input(k), f.instruction_output(k)
        a = f"w{i[0]}" if len(i) else ""
        c = f"w{i[1]}" if len(i) > 1 else ""
        if op == ca.OP_INPUT:
            e = (f"((vd){{0}} + in[{i[0]}][{i[1]}])" if i[0] in shared
                 else f"ld(in[{i[0]}] + {i[1] * LANES})")
        elif op == ca.OP_OUTPUT:
            lines.append(f"  st(out[{o[0]}] + {o[1] * LANES}, w{i[0]});")
            continue
        elif op == ca.OP_CONST:
            v = float(f.instruction_constant(k))
            lines.append(f"  w{o[0]} = (vd){{0}} + {_literal(v)};")
            const[o[0]] = v
            continue
        elif op in (ca.OP_POW, ca.OP_CONSTPOW):
            e = {0.5: f"vsqrt({a})", 0.25: f"vsqrt(vsqrt({a}))", 2.0: f"({a}*{a})",
                 1.0: a}.get(const.get(i[1]), "")
            if not e:
                raise ValueError(f"lanes: {f.name()}: a power other than 1/4, 1/2, 1, 2")
        else:
            e = {
                ca.OP_ADD: f"({a}+{c})", ca.OP_SUB: f"({a}-{c})", ca.OP_MUL: f"({a}*{c})",
                ca.OP_DIV: f"({a}/{c})", ca.OP_NEG: f"(-{a})", ca.OP_TWICE: f"({a}+{a})",
                ca.OP_SQ: f"({a}*{a})", ca.OP_INV: f"(ONE/{a})", ca.OP_SQRT: f"vsqrt({a})",
                ca.OP_FABS: f"vfabs({a})", ca.OP_ASSIGN: a,
                ca.OP_LT: b(f"({a}<{c})"), ca.OP_LE: b(f"({a}<={c})"),
                ca.OP_EQ: b(f"({a}=={c})"), ca.OP_NE: b(f"({a}!={c})"),
                ca.OP_NOT: b(f"({a}==ZERO)"),
                ca.OP_AND: b(f"(({a}!=ZERO)&({c}!=ZERO))"),
                ca.OP_OR: b(f"(({a}!=ZERO)|({c}!=ZERO))"),
                ca.OP_IF_ELSE_ZERO: f"sel({a}!=ZERO, {c}, ZERO)",
                ca.OP_FMAX: f"sel({a}!={a}, {c}, sel({c}!={c}, {a}, sel({a}>{c}, {a}, {c})))",
                ca.OP_FMIN: f"sel({a}!={a}, {c}, sel({c}!={c}, {a}, sel({a}<{c}, {a}, {c})))",
            }.get(op, "")
            if not e:
                raise ValueError(f"lanes: {f.name()}: operation "
                                 f"{_OP_NAMES.get(op, op)} not written")
        const.pop(o[0], None)
        lines.append(f"  w{o[0]} = {e};")
    lines.append("}")
    return "\n".join(lines) + "\n"


def single_sx(f: ca.Function, name: str | None = None) -> ca.Function:
    """``f`` as one SX graph (an MX Function expanded: its calls inlined, its branches
    selects) with its common subexpressions merged: the operations :func:`kernel` writes,
    for CasADi's own evaluation to match them."""
    g = f if f.is_a("SXFunction") else f.expand()
    ins = g.sx_in()
    outs = g(*ins)
    outs = [outs] if isinstance(outs, ca.SX) else list(outs)
    return ca.Function(name or f.name() + "_sx", ins, outs, {"cse": True})


def _cse(f: ca.Function) -> ca.Function:
    """``f`` as :func:`single_sx` gives it (an SX Function with merged subexpressions is
    taken as it is)."""
    return f if f.is_a("SXFunction") else single_sx(f)


def chunk_source(name: str, step: ca.Function, polish: ca.Function, width: int, npar: int,
                 steps: int) -> str:
    """C of a CasADi external Function ``name``: (S[LANES x width], par[npar]) ->
    (S'[LANES x width], cond[LANES]): ``steps`` calls of ``step`` ((state, par) -> state,
    a lane's state a row of S), then ``polish`` ((state, par) -> (state, cond)), for
    :data:`LANES` states at once (the dense matrices are column-major: the state's entry
    j of lane k at j * LANES + k, as :func:`kernel` reads them)."""
    st, po = _cse(step), _cse(polish)
    ops = st.n_instructions() + po.n_instructions()
    if ops > MAX_OPS:
        raise ValueError(f"lanes: {ops} operations in the step and polish (at most "
                         f"{MAX_OPS}: the compiler's time grows with them)")
    body = kernel(st, "k_step", shared=[1]) + kernel(po, "k_polish", shared=[1])
    n = LANES * width
    return _HEADER + body + f"""
#define EXPORT __attribute__((visibility("default")))
EXPORT int {name}(const casadi_real** arg, casadi_real** res, casadi_int* iw,
                  casadi_real* w, int mem) {{
  double a[{n}], b[{n}];
  const double* par = arg[1];
  if (arg[0]) memcpy(a, arg[0], sizeof a); else memset(a, 0, sizeof a);
  for (int s = 0; s < {steps}; ++s) {{
    const double* in[2] = {{a, par}};
    double* out[1] = {{b}};
    k_step(in, out);
    memcpy(a, b, sizeof a);
  }}
  {{
    double c[{LANES}];
    const double* in[2] = {{a, par}};
    double* out[2] = {{b, c}};
    k_polish(in, out);
    if (res[0]) memcpy(res[0], b, sizeof b);
    if (res[1]) memcpy(res[1], c, sizeof c);
  }}
  return 0;
}}
""" + _exports(name, 2, 2, [(LANES, width), (npar, 1)], [(LANES, width), (LANES, 1)],
               ["state", "par"], ["state", "cond"])


def _exports(name: str, n_in: int, n_out: int, sp_in: list[tuple[int, int]],
             sp_out: list[tuple[int, int]], names_in: list[str], names_out: list[str]) -> str:
    """CasADi's external-function entry points of ``name`` (dense inputs and outputs of
    the given shapes), but the evaluation itself."""
    maj, mnr, pat = (int(x) for x in (ca.__version__.split(".") + ["0", "0"])[:3])
    sp = "".join(f"static const casadi_int si{i}[3] = {{{r}, {c}, 1}};\n"
                 for i, (r, c) in enumerate(sp_in))
    sp += "".join(f"static const casadi_int so{i}[3] = {{{r}, {c}, 1}};\n"
                  for i, (r, c) in enumerate(sp_out))

    def pick(prefix: str, n: int) -> str:
        return " : ".join(f"i == {i} ? {prefix}{i}" for i in range(n)) + " : 0"

    def names(ns: list[str]) -> str:
        return " : ".join(f'i == {i} ? "{v}"' for i, v in enumerate(ns)) + " : 0"

    return sp + f"""EXPORT void {name}_casadi_version(int* major, int* minor, int* patch) {{
  *major = {maj}; *minor = {mnr}; *patch = {pat}; }}
EXPORT int {name}_casadi_int_size(void) {{ return (int) sizeof(casadi_int); }}
EXPORT int {name}_casadi_real_size(void) {{ return (int) sizeof(casadi_real); }}
EXPORT int {name}_checkout(void) {{ return 0; }}
EXPORT void {name}_release(int mem) {{ }}
EXPORT void {name}_incref(void) {{ }}
EXPORT void {name}_decref(void) {{ }}
EXPORT casadi_int {name}_n_in(void) {{ return {n_in}; }}
EXPORT casadi_int {name}_n_out(void) {{ return {n_out}; }}
EXPORT const char* {name}_name_in(casadi_int i) {{ return {names(names_in)}; }}
EXPORT const char* {name}_name_out(casadi_int i) {{ return {names(names_out)}; }}
EXPORT const casadi_int* {name}_sparsity_in(casadi_int i) {{ return {pick("si", n_in)}; }}
EXPORT const casadi_int* {name}_sparsity_out(casadi_int i) {{ return {pick("so", n_out)}; }}
EXPORT int {name}_work(casadi_int *sz_arg, casadi_int* sz_res, casadi_int *sz_iw,
                       casadi_int *sz_w) {{
  if (sz_arg) *sz_arg = {n_in}; if (sz_res) *sz_res = {n_out}; if (sz_iw) *sz_iw = 0;
  if (sz_w) *sz_w = 0; return 0; }}
"""


def function_source(name: str, f: ca.Function, shared: Sequence[int] = ()) -> str:
    """C of a CasADi external Function ``name`` evaluating ``f`` at :data:`LANES` points
    in one call: input ``i`` is a dense (LANES x nnz) matrix, one point a row (an input
    in ``shared``: its nonzeros, the same for every point), each output (LANES x nnz)."""
    g = _cse(f)
    shared = set(shared)
    n_in, n_out = g.n_in(), g.n_out()
    sp_in = [(g.nnz_in(i), 1) if i in shared else (LANES, g.nnz_in(i)) for i in range(n_in)]
    sp_out = [(LANES, g.nnz_out(i)) for i in range(n_out)]
    body = kernel(g, "k_eval", shared=shared)
    sizes_in = [r * c for r, c in sp_in]
    sizes_out = [r * c for r, c in sp_out]
    bufs = "".join(f"  double a{i}[{max(1, n)}];\n" for i, n in enumerate(sizes_in))
    bufs += "".join(f"  double r{i}[{max(1, n)}];\n" for i, n in enumerate(sizes_out))
    copy_in = "".join(
        f"  if (arg[{i}]) memcpy(a{i}, arg[{i}], sizeof a{i}); else memset(a{i}, 0, sizeof a{i});\n"
        for i in range(n_in))
    copy_out = "".join(f"  if (res[{i}]) memcpy(res[{i}], r{i}, sizeof r{i});\n"
                       for i in range(n_out))
    ins = ", ".join(f"a{i}" for i in range(n_in))
    outs = ", ".join(f"r{i}" for i in range(n_out))
    return _HEADER + body + f"""
#define EXPORT __attribute__((visibility("default")))
EXPORT int {name}(const casadi_real** arg, casadi_real** res, casadi_int* iw,
                  casadi_real* w, int mem) {{
{bufs}{copy_in}  {{
    const double* in[{max(1, n_in)}] = {{{ins}}};
    double* out[{max(1, n_out)}] = {{{outs}}};
    k_eval(in, out);
  }}
{copy_out}  return 0;
}}
""" + _exports(name, n_in, n_out, sp_in, sp_out, [g.name_in(i) for i in range(n_in)],
               [g.name_out(i) for i in range(n_out)])


def lanes_function(f: ca.Function, shared: Sequence[int] = (), wait: bool = True) -> Any:
    """``f`` compiled by :func:`function_source` (through the library cache), as a
    CasADi external Function of :data:`LANES` points a call; None where no compiler, cache
    or CPU key is available or the build failed; a pending library when ``wait`` is
    False and it is still being built."""
    from . import compiled as cc

    cpu = cpu_key()
    if cpu is None:
        return None
    shared = sorted(set(shared))
    name = "lanes_" + "".join(ch if ch.isalnum() else "_" for ch in f.name())
    ins = [ca.MX.sym(f"i{i}", f.nnz_in(i), 1) if i in shared else
           ca.MX.sym(f"i{i}", LANES, f.nnz_in(i)) for i in range(f.n_in())]
    ref = ca.Function(name, ins, [ca.MX.zeros(LANES, f.nnz_out(i)) for i in range(f.n_out())])
    tag = (f"lanes:{cc.fingerprint(f)[:16]}:{shared}:{source_digest()}:{cpu}:"
           f"{' '.join(FLAGS)}")
    lib = cc.start_library(tag, [ref], source=lambda: function_source(name, f, shared),
                           flags=FLAGS)
    if lib is None or isinstance(lib, dict):
        return None if lib is None else lib[name]
    if not wait:
        return lib
    out = lib.wait()
    return out[name] if out else None


def cpu_key() -> str | None:
    """What the cache key of a lanes library holds of the machine (its architecture and
    the CPU's feature flags, which ``-march=native`` compiles for), or None where it cannot
    be read (lanes are then not built)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            text = f.read(1 << 20)
    except OSError:
        return None
    flags = next((ln.split(":", 1)[1].strip() for ln in text.splitlines()
                  if ln.startswith(("flags", "Features"))), None)
    if not flags:
        return None
    h = hashlib.sha256(f"{platform.machine()}|{' '.join(sorted(flags.split()))}".encode())
    return h.hexdigest()[:16]


def source_digest() -> str:
    """SHA-256 (first 16 hex digits) of this writer's own code (part of the cache key)."""
    with open(os.path.abspath(__file__), "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:16]
