"""Complex evaluation of a model's Functions, compiled like the real ones.

Homotopy continuation tracks solutions through complex space; optkin's models are real
CasADi SX Functions. :func:`complexify` reads a Function's instruction list
(``Function.instruction_id/input/output/constant``) and builds a new SX Function in which
every value is a pair (real part, imaginary part) of real expressions: chosen inputs
become complex (two real inputs each), the others stay real (geometry, for example), and
every output becomes two (its real and imaginary parts). The result is an ordinary real
CasADi Function: it maps, differentiates and compiles to C like any other.

The operations are the holomorphic extensions: +, -, *, / and integer powers exactly;
sqrt, log and non-integer powers on their principal branches (cut along the negative real
axis: a closure written with squared distances never meets it); sin, cos, tan, exp, sinh,
cosh, tanh by their standard complex forms. Operations without a holomorphic extension
(abs, min, max, comparisons, atan2, floor) raise an error naming the operation.
Values known to be real (real inputs, constants, and what only they produce) carry no
imaginary part, so no work is spent on it.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca

__all__ = ["complexify"]

_NAMES = {getattr(ca, k): k[3:].lower() for k in dir(ca) if k.startswith("OP_")}


def _mul(a, b):
    (ar, ai), (br, bi) = a, b
    if ai is None and bi is None:
        return ar * br, None
    if ai is None:
        return ar * br, ar * bi
    if bi is None:
        return ar * br, ai * br
    return ar * br - ai * bi, ar * bi + ai * br


def _div(a, b):
    (ar, ai), (br, bi) = a, b
    if bi is None:
        return ar / br, (None if ai is None else ai / br)
    den = br * br + bi * bi
    if ai is None:
        return ar * br / den, -ar * bi / den
    return (ar * br + ai * bi) / den, (ai * br - ar * bi) / den


def _add(a, b, sign=1):
    (ar, ai), (br, bi) = a, b
    re = ar + br if sign > 0 else ar - br
    if ai is None and bi is None:
        return re, None
    ai = 0 if ai is None else ai
    bi = 0 if bi is None else bi
    return re, (ai + bi if sign > 0 else ai - bi)


def _exp(a):
    ar, ai = a
    if ai is None:
        return ca.exp(ar), None
    e = ca.exp(ar)
    return e * ca.cos(ai), e * ca.sin(ai)


def _log(a):
    ar, ai = a
    if ai is None:  # principal branch: log of a negative real is log|x| + i pi
        return ca.log(ca.fabs(ar)), ca.if_else(ar < 0, ca.pi, 0)
    return 0.5 * ca.log(ar * ar + ai * ai), ca.atan2(ai, ar)


def _sqrt(a):
    ar, ai = a
    if ai is None:
        return ca.sqrt(ca.fmax(ar, 0)), ca.sqrt(ca.fmax(-ar, 0))
    # principal branch (Re >= 0, Im of the sign of Im z), without cancellation:
    # t = sqrt((|z| + |Re z|) / 2), then the other part is Im z / (2 t)
    r = ca.sqrt(ar * ar + ai * ai)
    t = ca.sqrt((r + ca.fabs(ar)) / 2)
    q = ai / (2 * ca.fmax(t, 1e-300))
    sgn = ca.if_else(ai < 0, -1, 1)
    return ca.if_else(ar >= 0, t, ca.fabs(q)), ca.if_else(ar >= 0, q, sgn * t)


def _sin(a):
    ar, ai = a
    if ai is None:
        return ca.sin(ar), None
    return ca.sin(ar) * ca.cosh(ai), ca.cos(ar) * ca.sinh(ai)


def _cos(a):
    ar, ai = a
    if ai is None:
        return ca.cos(ar), None
    return ca.cos(ar) * ca.cosh(ai), -ca.sin(ar) * ca.sinh(ai)


def _sinh(a):
    ar, ai = a
    if ai is None:
        return ca.sinh(ar), None
    return ca.sinh(ar) * ca.cos(ai), ca.cosh(ar) * ca.sin(ai)


def _cosh(a):
    ar, ai = a
    if ai is None:
        return ca.cosh(ar), None
    return ca.cosh(ar) * ca.cos(ai), ca.sinh(ar) * ca.sin(ai)


def _ipow(a, n: int):
    """a ** n for an integer n (repeated squaring; n < 0 through 1 / a)."""
    if n < 0:
        return _div((ca.SX(1), None), _ipow(a, -n))
    out = (ca.SX(1), None)
    base = a
    while n:
        if n & 1:
            out = _mul(out, base)
        n >>= 1
        if n:
            base = _mul(base, base)
    return out


def _pow(a, b):
    br, bi = b
    if bi is None and br.is_constant():
        c = float(br)
        if c.is_integer() and abs(c) <= 64:
            return _ipow(a, int(c))
    return _exp(_mul(b, _log(a)))  # principal branch


def _unsupported(op):
    def f(*_):
        raise ValueError(f"complexify: the operation {_NAMES.get(op, op)} has no holomorphic "
                         "extension; write the model without it (e.g. squared distances "
                         "instead of abs, atan2 or min/max)")
    return f


_OPS = {
    ca.OP_ADD: lambda a, b: _add(a, b, 1),
    ca.OP_SUB: lambda a, b: _add(a, b, -1),
    ca.OP_MUL: _mul,
    ca.OP_DIV: _div,
    ca.OP_NEG: lambda a: (-a[0], None if a[1] is None else -a[1]),
    ca.OP_TWICE: lambda a: (2 * a[0], None if a[1] is None else 2 * a[1]),
    ca.OP_SQ: lambda a: _mul(a, a),
    ca.OP_INV: lambda a: _div((ca.SX(1), None), a),
    ca.OP_SQRT: _sqrt,
    ca.OP_EXP: _exp,
    ca.OP_LOG: _log,
    ca.OP_SIN: _sin,
    ca.OP_COS: _cos,
    ca.OP_TAN: lambda a: _div(_sin(a), _cos(a)),
    ca.OP_SINH: _sinh,
    ca.OP_COSH: _cosh,
    ca.OP_TANH: lambda a: _div(_sinh(a), _cosh(a)),
    ca.OP_POW: _pow,
    ca.OP_CONSTPOW: _pow,
    ca.OP_ASSIGN: lambda a: a,
}


def complexify(f: ca.Function, complex_inputs: Sequence[int | str] | None = None,
               name: str | None = None) -> ca.Function:
    """The holomorphic extension of the SX Function ``f`` as a real Function of real and
    imaginary parts.

    Parameters
    ----------
    f : casadi.Function
        An SX Function (a model's closure, Jacobian, ...).
    complex_inputs : sequence of int or str, optional
        The inputs that become complex (indices or names; default: all). Each becomes two
        inputs, ``<name>_re`` and ``<name>_im``, in place; the others stay real.
    name : str, optional
        Name of the new Function (default ``f.name() + "_complex"``).

    Returns
    -------
    casadi.Function
        Inputs as described; outputs ``<name>_re``, ``<name>_im`` for each output of ``f``.
    """
    if not f.is_a("SXFunction"):
        raise TypeError(f"complexify: needs an SX Function, got {f.class_name()} "
                        "(build the model's Functions from SX symbols)")
    n_in = f.n_in()
    if complex_inputs is None:
        cplx = set(range(n_in))
    else:
        cplx = {f.index_in(i) if isinstance(i, str) else int(i) for i in complex_inputs}
    args, sym_in = [], []
    for i in range(n_in):
        sp = f.sparsity_in(i)
        re = ca.SX.sym(f.name_in(i) + ("_re" if i in cplx else ""), sp)
        args.append(re)
        if i in cplx:
            im = ca.SX.sym(f.name_in(i) + "_im", sp)
            args.append(im)
            sym_in.append((re, im))
        else:
            sym_in.append((re, None))
    w: dict[int, tuple] = {}
    outs = [[(ca.SX(0), None)] * f.nnz_out(k) for k in range(f.n_out())]
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        i, o = f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            re, im = sym_in[i[0]]
            w[o[0]] = (re.nz[i[1]], None if im is None else im.nz[i[1]])
        elif op == ca.OP_OUTPUT:
            outs[o[0]][o[1]] = w[i[0]]
        elif op == ca.OP_CONST:
            w[o[0]] = (ca.SX(f.instruction_constant(k)), None)
        elif op == getattr(ca, "OP_PARAMETER", -1):
            raise ValueError("complexify: Functions with free parameters are not supported")
        else:
            fn = _OPS.get(op) or _unsupported(op)
            w[o[0]] = fn(*(w[j] for j in i))
    res, names = [], []
    for k in range(f.n_out()):
        sp = f.sparsity_out(k)
        re = ca.SX(sp)
        im = ca.SX(sp)
        for j, (a, b) in enumerate(outs[k]):
            re.nz[j] = a
            im.nz[j] = 0 if b is None else b
        res += [re, im]
        names += [f.name_out(k) + "_re", f.name_out(k) + "_im"]
    in_names = []
    for i in range(n_in):
        in_names += ([f.name_in(i) + "_re", f.name_in(i) + "_im"] if i in cplx
                     else [f.name_in(i)])
    return ca.Function(name or f.name() + "_complex", args, res, in_names, names)
