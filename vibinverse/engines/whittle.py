"""The frequency-domain engine: Whittle's likelihood of a long uniform record, computed from the
same block-diagonal state-space tables the Kalman engine runs (`vibinverse.engines.kalman`).

A model x_k = Phi x_{k-1} + w_k (w ~ N(0, Q)), y_k = h . x_k + v_k (v ~ N(0, r)) has the
spectral density (per sample, two-sided, angular frequency w in radians per sample, z = e^{iw})

    f(w) = h (zI - Phi)^{-1} Q (zI - Phi)^{-H} h' + r,

exact for the sampled process (aliasing included: the tables are the exact discretization). The
engine works on the first differences d_k = y_k - y_{k-1} (m = n - 1 of them), whose density is
c(w) f(w), c = |1 - z^{-1}|^2 = 4 sin^2(w / 2): a random walk's pole cancels (its differences are
white), the level drops out, and the walk's end-to-end jump does not leak into the periodogram.
Whittle's approximation of the Gaussian log-likelihood of d, with I_j = |sum_k d_k z_j^{-k}|^2 / m
at the Fourier frequencies w_j = 2 pi j / m, j = 1 .. (m - 1) / 2 (each a complex coefficient of two
degrees of freedom; the Nyquist ordinate, when m is even, one):

    log L = -(m - 1) / 2 log(2 pi) - sum_j [log f_j + I_j / f_j] - (Nyquist) 1/2 [log f_N + I_N / f_N].

The differences' transform at every ordinate is (e^{iw} - 1) Y_j + e^{iw} (y_m - y_0), Y_j the
record's: the stationary part's end-to-end jump J (variance ~2 v, v its variance) is one random
number shared by all ordinates, in the real part of X_j e^{-iw_j}. Counted as independent noise in
each ordinate (a density share 2 v / m), it misled the fit: on 40 min 10 Hz decimated building
records the strongest mode's damping intervals held the truth in 10 of 16 (its estimates' spread
2.6 times their sd). So the likelihood takes it as one shared Gaussian term (`shared_jump`: the exact
Gaussian likelihood of the ordinates under diag(f / 2) + tau^2 1 1', by Sherman-Morrison, tau^2 =
2 v / m): 15 of 16 there, the estimates' spread their sd. A model without a drift takes the record's
own periodogram (`differences` 0: no jump; `vibinverse.models.modal.whittle_engine`).

Lines (deterministic sinusoids a cos(theta k + psi)) leave the record's transform in closed form
(`line_transform`: a geometric sum per line and ordinate, no FFT and no pass over the samples).
Cost: O(blocks + lines) per ordinate, the record's FFT once;
the Kalman filter's O(states^2) per sample with a fixed point in its gain is ~10x dearer per call.
It holds for stationary Gaussian records long against the slowest correlation time (the order
search and fits of long uniform records: `vibinverse.models.modal`); gaps, irregular stamps and a
multiplicative gain drift need the Kalman engine.
"""

from __future__ import annotations

import math

import numpy as np

from vibinverse.engines.kalman import njit

_LOG_2PI = math.log(2.0 * math.pi)
#: a grouped periodogram (`Periodogram`, bins L) keeps its lowest UNGROUPED_PER_BIN x L ordinates
#: one to a group: there a group of L would span more than 1/16 of its own frequency
UNGROUPED_PER_BIN = 16


@njit(cache=True, inline="always", fastmath=False, nogil=True)
def block_terms(cwj, swj, a11, a12, a21, a22, h1, h2):  # pragma: no cover - compiled
    """At one ordinate (cos w, sin w) of a 2 x 2 block (Phi entries, observation h1, h2): M = zI - Phi's
    (M11, M22 real parts, their imaginary part sin w), h M^{-1}'s numerators n1 = h1 M22 - h2 M21,
    n2 = h2 M11 - h1 M12 (real, imaginary) and det M (real, imaginary)."""
    m11r, m22r, mi = cwj - a11, cwj - a22, swj
    n1r, n1i = h1 * m22r + h2 * a21, h1 * mi
    n2r, n2i = h2 * m11r + h1 * a12, h2 * mi
    detr = m11r * m22r - mi * mi - a12 * a21
    deti = (m11r + m22r) * mi
    return m11r, m22r, mi, n1r, n1i, n2r, n2i, detr, deti


@njit(cache=True, fastmath=False, nogil=True)
def spectral_density(cw, sw, c, diff, phi, q, h, r, starts, sizes, out):  # pragma: no cover - compiled
    """The series' spectral density f(w) (diff 0), or its first differences' c(w) f(w) (diff 1), at
    each ordinate (cw = cos w, sw = sin w, c = 4 sin^2(w / 2)), written into `out`; blocks of 1 or
    2 states start at `starts` (sizes). Block by block, each over every ordinate (a loop the compiler
    vectorizes: 3x faster than ordinate by ordinate). A 2 x 2 block's numerator q-weighted |h adj(zI -
    Phi)|^2 is linear in cos w, K0 + K1 cos w (adj's entries are h_i z + c_i): taken from its end
    where it is least, N + |K1| x (x = (1 - cos w) = c / 2 from w = 0 when K1 <= 0, else 1 + cos w
    from w = pi), a sum of nonnegatives as accurate as the full product, 1.6x faster on an hour at
    200 Hz (360,000 ordinates, three modes: 2.5 ms a density, was 4.1 ms)."""
    nj = cw.shape[0]
    for j in range(nj):
        out[j] = r * (c[j] if diff else 1.0)
    for b in range(starts.shape[0]):
        o = starts[b]
        if sizes[b] == 1:
            p, hq = phi[o, o], h[o] * h[o] * q[o, o]
            if hq == 0.0:
                continue
            one_p2 = (1.0 - p) * (1.0 - p)
            for j in range(nj):
                den = one_p2 + p * c[j]  # |z - p|^2: a walk (p = 1) gives c / c = 1 without cancelling
                if den > 0.0:  # 0 only for a walk at zero frequency, where it has no density
                    out[j] += hq * (c[j] if diff else 1.0) / den
        else:
            h1, h2 = h[o], h[o + 1]
            if h1 == 0.0 and h2 == 0.0:
                continue
            a11, a12, a21, a22 = phi[o, o], phi[o, o + 1], phi[o + 1, o], phi[o + 1, o + 1]
            q11, q12, q22 = q[o, o], q[o, o + 1], q[o + 1, o + 1]
            # M = zI - Phi; h adj(M) = (h1 z + c1, h2 z + c2); |.|^2 weighted by q: K0 + K1 cos w
            c1, c2 = h2 * a21 - h1 * a22, h1 * a12 - h2 * a11
            k1 = 2.0 * (q11 * h1 * c1 + q22 * h2 * c2 + q12 * (h1 * c2 + h2 * c1))
            far = k1 > 0.0  # the numerator is least at w = pi
            end = -1.0 if far else 1.0
            n1, n2 = h1 * end + c1, h2 * end + c2
            least = q11 * n1 * n1 + q22 * n2 * n2 + 2.0 * q12 * n1 * n2
            slope, a1221 = abs(k1), a12 * a21
            for j in range(nj):
                cwj, mi = cw[j], sw[j]
                m11r, m22r = cwj - a11, cwj - a22
                detr = m11r * m22r - mi * mi - a1221
                deti = (m11r + m22r) * mi
                x = (1.0 + cwj) if far else 0.5 * c[j]
                out[j] += (c[j] if diff else 1.0) * (least + slope * x) / (detr * detr + deti * deti)


@njit(cache=True, fastmath=False, nogil=True)
def pole_reach(m):  # pragma: no cover - compiled
    """How many ordinates either side of the nearest one a line's pole (s theta = w_j) can lie within
    1e-7 of (`line_transform`'s sines' branch): 1, plus the ordinates in 1e-7 rad on a very long record."""
    return 1 + math.ceil(1e-7 * m / (2.0 * math.pi))


@njit(cache=True, fastmath=False, nogil=True)
def pole_ordinate(theta, sign, m):  # pragma: no cover - compiled
    """The index j (w_j = 2 pi (j + 1) / m) of the ordinate nearest the pole of the line's `sign` half."""
    return round((sign * theta / (2.0 * math.pi)) % 1.0 * m) - 1


@njit(cache=True, fastmath=False, nogil=True)
def transform_coefficients(m, diff, theta, psi, amp):  # pragma: no cover - compiled
    """Per sign s = +1, -1 of `line_transform`: the coefficient (amp / 2) e^{i s psi} [(e^{i s theta} -
    1)] (cre, cim), it times (1 - e^{i m s theta}), the numerator (nre, nim), and e^{i s theta} (ere, eim)."""
    cre, cim, nre, nim, ere, eim = np.empty(2), np.empty(2), np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    for s in range(2):
        sg = 1.0 if s == 0 else -1.0
        th, ph = sg * theta, sg * psi
        ar, ai = 0.5 * amp * math.cos(ph), 0.5 * amp * math.sin(ph)
        if diff:
            dr, di = math.cos(th) - 1.0, math.sin(th)
            ar, ai = ar * dr - ai * di, ar * di + ai * dr
        br, bi = 1.0 - math.cos(m * th), -math.sin(m * th)
        cre[s], cim[s] = ar, ai
        nre[s], nim[s] = ar * br - ai * bi, ar * bi + ai * br
        ere[s], eim[s] = math.cos(th), math.sin(th)
    return cre, cim, nre, nim, ere, eim


@njit(cache=True, fastmath=False, nogil=True, inline="always", error_model="numpy")
def half_sum(c, s, er, ei, nr, ni):  # pragma: no cover - compiled
    """One sign's geometric sum N / Q at the ordinate (cos w, sin w) = (c, s), Q = 1 - e^{i s theta}
    e^{-i w} (e^{i s theta} = er + i ei, N = nr + i ni): (Re, Im, |Q|^2); inf on the pole, where
    |Q|^2 is 0 (`transform_at` then takes the sines)."""
    qr = 1.0 - (er * c + ei * s)
    qi = -(ei * c - er * s)
    den = qr * qr + qi * qi
    return (nr * qr + ni * qi) / den, (ni * qr - nr * qi) / den, den


@njit(cache=True, fastmath=False, nogil=True, error_model="numpy")
def transform_at(j, cw, sw, m, theta, cre, cim, nre, nim, ere, eim):  # pragma: no cover - compiled
    """`line_transform` at ordinate j, each half by its geometric sum or, within 1e-7 of its pole, by
    its sines: (real, imaginary)."""
    tr, ti = 0.0, 0.0
    for s in range(2):
        xr, xi, den = half_sum(cw[j], sw[j], ere[s], eim[s], nre[s], nim[s])
        if den > 1e-14:
            tr += xr
            ti += xi
        else:  # on (or next to) the ordinate: the sum by its sines
            sg = 1.0 if s == 0 else -1.0
            d = sg * theta - 2.0 * math.pi * (j + 1) / m
            d = d - 2.0 * math.pi * round(d / (2.0 * math.pi))
            half = math.sin(0.5 * d)
            mag = float(m) if abs(half) < 1e-300 else math.sin(0.5 * m * d) / half
            kr, ki = mag * math.cos(0.5 * (m - 1) * d), mag * math.sin(0.5 * (m - 1) * d)
            tr += cre[s] * kr - cim[s] * ki
            ti += cre[s] * ki + cim[s] * kr
    return tr, ti


@njit(cache=True, fastmath=False, nogil=True, error_model="numpy")
def line_transform(cw, sw, m, diff, theta, psi, amp, out):  # pragma: no cover - compiled
    """The transform (ordinates j = 1 ..) of the line amp cos(theta k + psi), k = 0 .. (theta
    radians per sample, psi the phase at the first sample), or of its differences (diff 1), into
    the complex `out`. With cos = (e^{i.} + e^{-i.}) / 2 each half is a geometric sum over the m
    values, sum_k e^{i (s theta - w_j) k} = (1 - e^{i m s theta}) / (1 - e^{i s theta} e^{-i w_j})
    (s = +-1, e^{-i m w_j} = 1), a difference multiplying the line by (e^{i s theta} - 1): one
    complex division per sign and ordinate from cw = cos w_j, sw = sin w_j. Within 1e-7 of a pole
    (a line on an ordinate) the sum is e^{i (m - 1) d / 2} sin(m d / 2) / sin(d / 2),
    d = s theta - w_j (m at d = 0). Every ordinate by the geometric sums in a loop without a branch
    (the compiler vectorizes it: 5x faster), then the few next to a pole again (`transform_at`):
    the same numbers as ordinate by ordinate."""
    cre, cim, nre, nim, ere, eim = transform_coefficients(m, diff, theta, psi, amp)
    e0r, e0i, e1r, e1i = ere[0], eim[0], ere[1], eim[1]
    n0r, n0i, n1r, n1i = nre[0], nim[0], nre[1], nim[1]
    nj = out.shape[0]
    for j in range(nj):
        c, s = cw[j], sw[j]
        xr, xi, _ = half_sum(c, s, e0r, e0i, n0r, n0i)  # inf on a pole: that ordinate is done again below
        tr, ti = 0.0 + xr, 0.0 + xi
        xr, xi, _ = half_sum(c, s, e1r, e1i, n1r, n1i)
        out[j] = complex(tr + xr, ti + xi)
    reach = pole_reach(m)
    for s in range(2):
        k = pole_ordinate(theta, 1.0 if s == 0 else -1.0, m)
        for j in range(max(k - reach, 0), min(k + reach + 1, nj)):
            tr, ti = transform_at(j, cw, sw, m, theta, cre, cim, nre, nim, ere, eim)
            out[j] = complex(tr, ti)


@njit(cache=True, fastmath=False, nogil=True)
def block_gradient(cw, sw, c, diff, phi, q, h, o, size, slope, out):  # pragma: no cover - compiled
    """sum_j slope_j d f_j / d e for each table entry e of the block of `size` 1 or 2 states at
    state o (`spectral_density`'s share of it, times c(w) when diff), analytically in one pass
    over the ordinates, into `out`: (phi, q) of a 1 x 1 block, (a11, a12, a21, a22, q11, q12, q22)
    of a 2 x 2 one (q12 the upper entry: Q is symmetric). Its share is a rational function of
    the entries at each ordinate: h^2 q / |z - phi|^2, or |h adj(M)|_Q^2 / |det M|^2 (M = zI - Phi)."""
    out[:] = 0.0
    nj = cw.shape[0]
    if size == 1:
        hh = h[o] * h[o]
        if hh == 0.0:
            return
        p, qq = phi[o, o], q[o, o]
        one_p = 1.0 - p
        gp, gq = 0.0, 0.0
        for j in range(nj):
            den = one_p * one_p + p * c[j]  # |z - p|^2
            if den > 0.0:
                u = slope[j] * hh * (c[j] if diff else 1.0) / den
                gq += u
                gp += u * qq * (2.0 * one_p - c[j]) / den  # d den / d p = c - 2 (1 - p)
        out[0], out[1] = gp, gq
        return
    h1, h2 = h[o], h[o + 1]
    if h1 == 0.0 and h2 == 0.0:
        return
    a11, a12, a21, a22 = phi[o, o], phi[o, o + 1], phi[o + 1, o], phi[o + 1, o + 1]
    q11, q12, q22 = q[o, o], q[o, o + 1], q[o + 1, o + 1]
    g11, g12, g21, g22, gq11, gq12, gq22 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for j in range(nj):
        m11r, m22r, mi, n1r, n1i, n2r, n2i, detr, deti = block_terms(cw[j], sw[j], a11, a12, a21, a22, h1, h2)
        s1, s2, s12 = n1r * n1r + n1i * n1i, n2r * n2r + n2i * n2i, n1r * n2r + n1i * n2i
        num = q11 * s1 + q22 * s2 + 2.0 * q12 * s12
        dd = detr * detr + deti * deti
        inv = 1.0 / dd
        u = slope[j] * (c[j] if diff else 1.0) * inv  # d f / d x = u (d num / d x - f d dd / d x)
        f = num * inv
        gq11 += u * s1
        gq22 += u * s2
        gq12 += u * 2.0 * s12
        p1 = 2.0 * (q11 * n1r + q12 * n2r)  # d num / d n1r
        p2 = 2.0 * (q22 * n2r + q12 * n1r)  # d num / d n2r
        e2, f2 = 2.0 * detr, 2.0 * deti  # dd = detr^2 + deti^2
        g11 += u * (-h2 * p2 + f * (e2 * m22r + f2 * mi))
        g22 += u * (-h1 * p1 + f * (e2 * m11r + f2 * mi))
        g12 += u * (h1 * p2 + f * e2 * a21)
        g21 += u * (h2 * p1 + f * e2 * a12)
    out[0], out[1], out[2], out[3] = g11, g12, g21, g22
    out[4], out[5], out[6] = gq11, gq12, gq22


@njit(cache=True, fastmath=False, nogil=True)
def gradient_coefficients(m, diff, theta, psi):  # pragma: no cover - compiled
    """Per sign s = +1, -1 of `line_gradient`: A = (1 / 2) e^{i s psi} [(e^{i s theta} - 1)] (cre,
    cim), dA / d (s theta) (dare, daim), N = A (1 - e^{i m s theta}) (nre, nim), dN / d (s theta)
    (dnre, dnim) and e^{i s theta} (ere, eim)."""
    cre, cim, dare, daim, nre = np.empty(2), np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    nim, dnre, dnim, ere, eim = np.empty(2), np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    for s in range(2):
        sg = 1.0 if s == 0 else -1.0
        th, ph = sg * theta, sg * psi
        ar, ai = 0.5 * math.cos(ph), 0.5 * math.sin(ph)
        er, ei = math.cos(th), math.sin(th)
        if diff:  # A = A0 (e^{i th} - 1), dA = A0 i e^{i th}
            dar, dai = -(ar * ei + ai * er), ar * er - ai * ei
            ar, ai = ar * (er - 1.0) - ai * ei, ar * ei + ai * (er - 1.0)
        else:
            dar, dai = 0.0, 0.0
        cmt, smt = math.cos(m * th), math.sin(m * th)
        br, bi = 1.0 - cmt, -smt  # B = 1 - e^{i m th}, dB = -i m e^{i m th}
        dbr, dbi = m * smt, -m * cmt
        cre[s], cim[s], dare[s], daim[s] = ar, ai, dar, dai
        nre[s], nim[s] = ar * br - ai * bi, ar * bi + ai * br
        dnre[s] = dar * br - dai * bi + ar * dbr - ai * dbi
        dnim[s] = dar * bi + dai * br + ar * dbi + ai * dbr
        ere[s], eim[s] = er, ei
    return cre, cim, dare, daim, nre, nim, dnre, dnim, ere, eim


@njit(cache=True, fastmath=False, nogil=True, inline="always", error_model="numpy")
def half_quotient(c, s, er, ei, nr, ni, dr, di):  # pragma: no cover - compiled
    """One sign's X = N / Q and dX / d (s theta) = (dN - X dQ) / Q at the ordinate (cos w, sin w) =
    (c, s), Q = 1 - e^{i s theta} e^{-i w} (e^{i s theta} = er + i ei, N = nr + i ni, dN = dr + i di,
    dQ = i (Q - 1)): (Re X, Im X, Re dX, Im dX, |Q|^2); inf on the pole, where |Q|^2 is 0
    (`gradient_at` then takes the sines)."""
    qr = 1.0 - (er * c + ei * s)
    qi = -(ei * c - er * s)
    den = qr * qr + qi * qi
    inv = 1.0 / den
    xr = (nr * qr + ni * qi) * inv
    xi = (ni * qr - nr * qi) * inv
    dqr, dqi = -qi, qr - 1.0
    ur = dr - (xr * dqr - xi * dqi)
    ui = di - (xr * dqi + xi * dqr)
    return xr, xi, (ur * qr + ui * qi) * inv, (ui * qr - ur * qi) * inv, den


@njit(cache=True, fastmath=False, nogil=True, error_model="numpy")
def gradient_at(j, cw, sw, m, theta, wre, wim, k):  # pragma: no cover - compiled
    """`line_gradient`'s terms at ordinate j (k: `gradient_coefficients`), each half by its quotient
    or, within 1e-7 of its pole, by its sines: (w . X, w . dX / d theta, and the psi slope's share
    of each sign)."""
    cre, cim, dare, daim, nre, nim, dnre, dnim, ere, eim = k
    tr, ti, ttr, tti = 0.0, 0.0, 0.0, 0.0  # X and dX / d theta at this ordinate
    share = np.empty(2)
    for s in range(2):
        sg = 1.0 if s == 0 else -1.0
        xr, xi, dxr, dxi, den = half_quotient(cw[j], sw[j], ere[s], eim[s], nre[s], nim[s], dnre[s], dnim[s])
        if not den > 1e-14:  # on (or next to) the ordinate: X = A K(d), d = s theta - w_j
            d = sg * theta - 2.0 * math.pi * (j + 1) / m
            d = d - 2.0 * math.pi * round(d / (2.0 * math.pi))
            half = math.sin(0.5 * d)
            x = 0.5 * d
            if abs(half) < 1e-300:
                mag, dmag = float(m), 0.0
            else:
                mag = math.sin(0.5 * m * d) / half
                if abs(m * x) < 1e-3:  # R' = (m / 2) [(1 - m^2) x / 3 + 4 x^3 (7 / 360 - m^2 / 36 + m^4 / 120)]
                    mm = float(m) * float(m)
                    dmag = 0.5 * m * ((1.0 - mm) * x / 3.0 + 4.0 * x**3 * (7.0 / 360.0 - mm / 36.0 + mm * mm / 120.0))
                else:
                    dmag = 0.5 * (m * math.cos(m * x) * half - math.sin(m * x) * math.cos(x)) / (half * half)
            ca, sa = math.cos(0.5 * (m - 1) * d), math.sin(0.5 * (m - 1) * d)
            kr, ki = mag * ca, mag * sa
            hm = 0.5 * (m - 1) * mag  # dK = e^{i a} (dmag + i hm)
            dkr, dki = dmag * ca - hm * sa, dmag * sa + hm * ca
            xr = cre[s] * kr - cim[s] * ki
            xi = cre[s] * ki + cim[s] * kr
            dxr = dare[s] * kr - daim[s] * ki + cre[s] * dkr - cim[s] * dki
            dxi = dare[s] * ki + daim[s] * kr + cre[s] * dki + cim[s] * dkr
        tr += xr
        ti += xi
        ttr += sg * dxr
        tti += sg * dxi
        share[s] = sg * (-wre[j] * xi + wim[j] * xr)  # d X / d psi = i s X
    return wre[j] * tr + wim[j] * ti, wre[j] * ttr + wim[j] * tti, share[0], share[1]


@njit(cache=True, fastmath=False, nogil=True, error_model="numpy")
def line_gradient(cw, sw, m, diff, theta, psi, wre, wim, out):  # pragma: no cover - compiled
    """For the unit line cos(theta k + psi) (`line_transform` with amp 1, X_j its transform):
    out = sum_j wre_j Re(Y_j) + wim_j Im(Y_j) for Y = X, dX / d theta and dX / d psi, analytically,
    no complex array built. dX / d psi = i s X per sign s; per sign, X = N / Q gives dX / d theta =
    s (dN - X dQ) / Q (N = A (1 - e^{i m s theta}), Q = 1 - e^{i s theta} e^{-i w_j}); next to a pole
    (`line_transform`'s sines) X = A K(d), dK / dd = e^{i (m - 1) d / 2} (i (m - 1) / 2 R + R'),
    R = sin(m d / 2) / sin(d / 2) (R' by its Taylor series for small m d). Each ordinate's terms
    by the quotients in a loop without a branch (vectorized), the few next to a pole again
    (`gradient_at`), then summed in the ordinates' order: the same numbers as ordinate by ordinate,
    3x faster."""
    k = gradient_coefficients(m, diff, theta, psi)
    _, _, _, _, nre, nim, dnre, dnim, ere, eim = k
    e0r, e0i, e1r, e1i = ere[0], eim[0], ere[1], eim[1]
    n0r, n0i, n1r, n1i = nre[0], nim[0], nre[1], nim[1]
    d0r, d0i, d1r, d1i = dnre[0], dnim[0], dnre[1], dnim[1]
    nj = cw.shape[0]
    terms = np.empty((4, nj))  # per ordinate: w . X, w . dX / d theta, the psi slope's share per sign
    for j in range(nj):
        c, s = cw[j], sw[j]
        xr, xi, dxr, dxi, _ = half_quotient(c, s, e0r, e0i, n0r, n0i, d0r, d0i)  # sign +1
        tr, ti = 0.0 + xr, 0.0 + xi
        ttr, tti = 0.0 + 1.0 * dxr, 0.0 + 1.0 * dxi
        terms[2, j] = 1.0 * (-wre[j] * xi + wim[j] * xr)
        xr, xi, dxr, dxi, _ = half_quotient(c, s, e1r, e1i, n1r, n1i, d1r, d1i)  # sign -1
        tr += xr
        ti += xi
        ttr += -1.0 * dxr
        tti += -1.0 * dxi
        terms[3, j] = -1.0 * (-wre[j] * xi + wim[j] * xr)
        terms[0, j] = wre[j] * tr + wim[j] * ti
        terms[1, j] = wre[j] * ttr + wim[j] * tti
    reach = pole_reach(m)
    for s in range(2):
        p = pole_ordinate(theta, 1.0 if s == 0 else -1.0, m)
        for j in range(max(p - reach, 0), min(p + reach + 1, nj)):
            terms[0, j], terms[1, j], terms[2, j], terms[3, j] = gradient_at(j, cw, sw, m, theta, wre, wim, k)
    g0, gt, gp = 0.0, 0.0, 0.0
    for j in range(nj):
        gp += terms[2, j]
        gp += terms[3, j]
        g0 += terms[0, j]
        gt += terms[1, j]
    out[0], out[1], out[2] = g0, gt, gp


@njit(cache=True, fastmath=False, nogil=True)
def dot(a, b):  # pragma: no cover - compiled
    """sum_j a_j b_j in one thread (a BLAS dot spins threads up: 3-5x slower on a busy machine), in
    eight running sums added pairwise at the end: independent chains the processor overlaps (2.5x
    faster than one running sum at 360,000 terms) and closer to the exact sum."""
    n = a.shape[0]
    s = np.zeros(8)
    k = n - n % 8
    for j in range(0, k, 8):
        for i in range(8):
            s[i] += a[j + i] * b[j + i]
    rest = 0.0
    for j in range(k, n):
        rest += a[j] * b[j]
    return ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7])) + rest


def lines_sum(k: int, theta: np.ndarray, psi: np.ndarray, amp: np.ndarray) -> float:
    """sum_{i < k} of the lines amp cos(theta i + psi), in closed form:
    sin(k theta / 2) / sin(theta / 2) cos(psi + (k - 1) theta / 2) per line (k cos psi at theta = 0)."""
    th = np.asarray(theta, dtype=float)
    half = np.sin(0.5 * th)
    tiny = np.abs(half) < 1e-300
    ratio = np.where(tiny, float(k), np.sin(0.5 * k * th) / np.where(tiny, 1.0, half))
    return float(
        np.sum(np.asarray(amp, dtype=float) * ratio * np.cos(np.asarray(psi, dtype=float) + 0.5 * (k - 1) * th))
    )


def fast_length(m: int) -> int:
    """The largest length <= m whose only prime factors are 2, 3, 5, 7 and 11 (the FFT's own radices):
    the values beyond it, at most ~0.2 % of a long record, are left out (a prime length takes the
    FFT 7-10x longer: 305 ms against 46 ms at 720,000 samples)."""
    k = int(m)
    while k > 1:
        r = k
        for p in (2, 3, 5, 7, 11):
            while r % p == 0:
                r //= p
        if r == 1:
            return k
        k -= 1
    return max(k, 1)


def shared_jump(inverse: np.ndarray, rotated: np.ndarray, tau2: float) -> tuple[float, float, float, float]:
    """The share in Whittle's log-likelihood of the differences' end-to-end jump (module docstring),
    one shared term instead of an independent share of every ordinate: with a = 2 sum_b W_b / f_b,
    b = 2 sum_b W_b x_b / f_b (`inverse` W_b / f_b, `rotated` x_b the groups' mean of
    `Periodogram.rotated`) and g = 1 + tau^2 a,

        C = -1/2 log g + tau^2 b^2 / (2 g)

    (Sherman-Morrison on the real parts' covariance diag(f / 2) + tau^2 1 1'). Returns (C, dC/da,
    dC/db, dC/dtau^2): the density's slope adds -2 W_b / f_b^2 (dC/da + dC/db x_b), a line's the
    real parts' dC/db 2 W_b / f_b."""
    a = 2.0 * float(np.sum(inverse))
    b = 2.0 * float(dot(inverse, rotated))  # one thread: BLAS's dot woke its threads, ~3.7 ms a call
    g = 1.0 + tau2 * a
    value = -0.5 * math.log(g) + 0.5 * tau2 * b * b / g
    return value, -0.5 * tau2 / g - 0.5 * (tau2 * b / g) ** 2, tau2 * b / g, -0.5 * a / g + 0.5 * (b / g) ** 2


class Periodogram:
    """The periodogram of a uniform record of n samples (`differences` 0), or of its first
    differences (1: a model with a random walk), at the Fourier frequencies j = 1 .. m / 2 of its
    first m values (m = `fast_length`(n - differences)) (`Periodogram.of`), and the likelihood
    under a model's tables.

    `bins` L > 1 groups the ordinates L at a time above the lowest `UNGROUPED_PER_BIN` L (the last
    group may be shorter) and takes the density as constant over a group, at its centre frequency:
    Whittle's sum over a group is then W_b (log f_b + mean I / f_b) (W_b the group's ordinate
    weights), the likelihood of the averaged periodogram (Welch's, without overlap), ~L times cheaper
    per call. It approximates the exact sum where the density curves within a group: relative
    error ~ (L dw / half-width)^2 / 12 per ordinate of a resonance (dw the ordinate spacing), < 0.1 %
    where a peak's half-power half-width spans 10 groups (`vibinverse.model_order.search_bins`); a
    smooth density (log slope <= 2 / w: coloured noise, a drift's corner) varies by <= 2 / 16 over a
    group above the ungrouped ordinates. The record's transform, its lines and their gradients stay
    on every ordinate (`reduce` averages per-ordinate values into groups, `expand` repeats a
    group's value over its ordinates).

    `top` (cycles per sample, None: Nyquist) keeps the ordinates at or below it: Whittle's
    likelihood of the band below a logger's anti-alias roll-off (`vibinverse.spectrum.passband_top`),
    where the record's density is the model's; above it the filter, not the model, shapes it."""

    def __init__(self, n: int, differences: int, bins: int = 1, top: float | None = None):
        if differences not in (0, 1):
            raise ValueError(f"differences: {differences}; allowed: 0 or 1")
        if int(bins) < 1:
            raise ValueError(f"bins: {bins}; allowed: 1 or more")
        if top is not None and not 0.0 < top <= 0.5:
            raise ValueError(f"top: {top}; allowed: in (0, 0.5] cycles per sample, or None")
        self.differences = differences
        self.m = fast_length(int(n) - differences)
        count = self.m // 2
        if top is not None:  # the ordinates at or below `top` cycles per sample (at least one)
            count = max(1, min(count, math.floor(top * self.m + 1e-9)))
        j = np.arange(1, count + 1)
        w = 2.0 * np.pi * j / self.m
        self.cw, self.sw = np.cos(w), np.sin(w)
        self.c = 4.0 * np.sin(0.5 * w) ** 2
        self.nyquist = self.m % 2 == 0 and count == self.m // 2
        #: each ordinate's weight in Whittle's sum: 1, the Nyquist ordinate 1/2
        self.ordinate_weights = np.ones(j.size)
        if self.nyquist:
            self.ordinate_weights[-1] = 0.5
        #: the sum of the ordinates' weights: (m - 1) / 2 on the whole band
        self.degrees = float(self.ordinate_weights.sum())
        self.bins = int(bins)
        if self.bins == 1:  # the group arrays are the ordinates' own
            self.group_cw, self.group_sw, self.group_c = self.cw, self.sw, self.c
            self.group_weights = self.ordinate_weights
            self.group_starts = np.arange(j.size)
            return
        single = min(UNGROUPED_PER_BIN * self.bins, j.size)
        self.group_starts = np.concatenate((np.arange(single), np.arange(single, j.size, self.bins)))
        counts = np.diff(np.append(self.group_starts, j.size))
        centre = 2.0 * np.pi * (self.group_starts + 1 + 0.5 * (counts - 1)) / self.m
        self.group_cw, self.group_sw = np.cos(centre), np.sin(centre)
        self.group_c = 4.0 * np.sin(0.5 * centre) ** 2
        self.group_weights = np.add.reduceat(self.ordinate_weights, self.group_starts)
        self._counts = counts

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """Per group, the ordinate-weighted mean of the per-ordinate values x (x itself when bins = 1)."""
        if self.bins == 1:
            return x
        return np.add.reduceat(x * self.ordinate_weights, self.group_starts) / self.group_weights

    def expand(self, x: np.ndarray) -> np.ndarray:
        """A per-group value on each of its ordinates (x itself when bins = 1)."""
        if self.bins == 1:
            return x
        return np.repeat(x, self._counts)

    def transform(self, y: np.ndarray) -> np.ndarray:
        """The discrete Fourier transform of y (length n), or of its first differences, at the
        ordinates j = 1 .. m / 2."""
        d = np.diff(np.asarray(y, dtype=float)) if self.differences else np.asarray(y, dtype=float)
        return np.fft.rfft(d[: self.m])[1 : self.c.size + 1]

    def of(self, y: np.ndarray) -> np.ndarray:
        """I_j of y (length n), or of its first differences."""
        spec = self.transform(y)
        return (spec.real**2 + spec.imag**2) / self.m

    def line_transform(self, theta: float, psi: float, amp: float) -> np.ndarray:
        """The `transform` of the line amp cos(theta k + psi) in closed form (`line_transform`)."""
        out = np.empty(self.c.size, dtype=complex)
        line_transform(self.cw, self.sw, self.m, self.differences, theta, psi, amp, out)
        return out

    def line_gradient(self, theta: float, psi: float, wre: np.ndarray, wim: np.ndarray) -> np.ndarray:
        """(sum_j wre_j Re Y_j + wim_j Im Y_j) for Y = the unit line's `transform` and its derivatives in
        theta and psi (`line_gradient`), one pass over the ordinates."""
        out = np.empty(3)
        line_gradient(self.cw, self.sw, self.m, self.differences, theta, psi, wre, wim, out)
        return out

    def block_gradient(
        self, phi: np.ndarray, q: np.ndarray, h: np.ndarray, o: int, size: int, slope: np.ndarray
    ) -> np.ndarray:
        """sum_j slope_j d f_j / d e for each table entry e of one block (`block_gradient`; 2 values
        for a 1 x 1 block, 7 for a 2 x 2 one), one pass over the ordinates."""
        out = np.empty(7)
        block_gradient(
            self.group_cw, self.group_sw, self.group_c, self.differences, phi, q, h, int(o), int(size), slope, out
        )
        return out[: 2 if size == 1 else 7]

    def ordinate_inverse(self, density: np.ndarray, inverse: np.ndarray) -> np.ndarray:
        """w_j / f_j on every ordinate from a group density and its `weights`' inverse w_b / f_b."""
        return inverse if self.bins == 1 else self.expand(1.0 / density) * self.ordinate_weights

    def rotated(self, spec: np.ndarray) -> np.ndarray:
        """x_j = Re(X_j e^{-i w_j}) / sqrt(m) of a `transform` of the differences: the part the
        record's end-to-end jump adds to (J / sqrt(m) at every ordinate: `shared_jump`)."""
        return (spec.real * self.cw + spec.imag * self.sw) / math.sqrt(self.m)

    def power(self, spec: np.ndarray) -> np.ndarray:
        """I_j = |spec_j|^2 / m of a `transform`."""
        return (spec.real**2 + spec.imag**2) / self.m

    def density(
        self, phi: np.ndarray, q: np.ndarray, h: np.ndarray, r: float, starts: np.ndarray, sizes: np.ndarray
    ) -> np.ndarray:
        """The density (module docstring) at the ordinates under the one-step tables (phi, q),
        observation row h, white variance r and the blocks (starts, sizes); of the differences,
        times c(w) (their end-to-end jump apart: `shared_jump`). A new array each call (threads
        evaluate walkers at once)."""
        density = np.empty(self.group_c.size)
        spectral_density(
            self.group_cw, self.group_sw, self.group_c, self.differences, phi, q, h, r, starts, sizes, density
        )
        return density

    def whittle(self, power: np.ndarray, density: np.ndarray) -> float:
        """Whittle's log-likelihood (module docstring) of the periodogram `power` under `density`
        (`density`), the zero frequency left out."""
        return self.weighted(power, self.weights(density))

    def weights(self, density: np.ndarray) -> tuple[np.ndarray, float]:
        """(w_b / f_b, sum_b w_b log f_b + (m - 1) / 2 log 2 pi) of a density at the groups
        (`group_weights` w_b: per ordinate 1, 1/2 at Nyquist, summed over a group): Whittle's
        likelihood of any (`reduce`d) periodogram is then one dot product (`weighted`); (empty, inf)
        when a density is <= 0."""
        if not np.all(density > 0.0):
            return np.empty(0), math.inf
        w = self.group_weights
        return w / density, float(dot(w, np.log(density)) + self.degrees * _LOG_2PI)

    @staticmethod
    def weighted(power: np.ndarray, weights: tuple[np.ndarray, float]) -> float:
        """Whittle's log-likelihood of `power` under a density's `weights` (-inf under none)."""
        inverse, constant = weights
        return -math.inf if not math.isfinite(constant) else float(-(constant + dot(power, inverse)))

    def zero_density(
        self, phi: np.ndarray, q: np.ndarray, h: np.ndarray, r: float, starts: np.ndarray, sizes: np.ndarray
    ) -> float:
        """f(0), the model's stationary part's density at zero frequency (a walk left out)."""
        f0 = np.empty(1)
        spectral_density(np.ones(1), np.zeros(1), np.zeros(1), 0, phi, q, h, r, starts, sizes, f0)
        return float(f0[0])


def walk_step_variance(phi: np.ndarray, q: np.ndarray, h: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> float:
    """The step variance the model's random walks add to the observation: h_i^2 Q_ii of each seen
    1 x 1 block whose transition is 1 (0 without a walk)."""
    out = 0.0
    for o, size in zip(starts, sizes):
        if size == 1 and phi[o, o] == 1.0 and h[o] != 0.0:
            out += float(h[o] * h[o] * q[o, o])
    return out


def level_window(f0: float, step_variance: float, n: int) -> int:
    """The leading samples whose mean carries the level best: the whole record without a walk, else
    K = sqrt(3 f(0) / q) (the stationary part's share of the mean's variance f(0) / K against the
    walk's q K / 3), within 1..n."""
    if not step_variance > 0.0:
        return int(n)
    return int(min(n, max(1, round(math.sqrt(3.0 * max(f0, 0.0) / step_variance)))))


def level_term(window_mean: float, window: int, f0: float, variance: float, step_variance: float) -> float:
    """The level's share of the likelihood: the mean residual of the first `window` samples
    ~ N(0, min(f(0) / K, v) + q K / 3) (v the stationary part's variance, q the walk's step
    variance; the walk starts at 0)."""
    var = min(max(f0, 0.0) / window, variance) + step_variance * window / 3.0
    if not var > 0.0:
        return -math.inf
    return float(-0.5 * (_LOG_2PI + math.log(var) + window_mean * window_mean / var))


def block_layout(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, sizes) of the diagonal blocks from each state's block bounds (lo[i], hi[i])."""
    lo = np.asarray(lo, dtype=np.int64)
    hi = np.asarray(hi, dtype=np.int64)
    first = np.flatnonzero(lo == np.arange(lo.size))
    return first.astype(np.int64), (hi[first] - lo[first]).astype(np.int64)
