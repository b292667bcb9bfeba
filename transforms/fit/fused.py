"""The objective's inner loops compiled (numba): a batch of candidates scored on the sample
in one pass per candidate, and one candidate's energy gradient, with no ``(k, n)``
temporaries.

On the fit's sample (a few hundred faces) numpy's cost is its per-call overhead, dozens of
calls per batch; these loops do the same arithmetic as :class:`.objective._Angles`,
:meth:`.objective._FaceShapes.sums` and :func:`.objective._energy_gradient` (the same
formulas in the same order, so the results agree to rounding: the sums are added in another
order). The separable method, whose angles come from a root search, stays in numpy.

Compiled on first use and cached on disk (``cache=True``); :func:`transforms.kernels.
compile_kernels` pays the compilation (seconds; loading from the cache, well under one)
outside a request, at start-up and in the image's build.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..faces import DEGENERATE_RTOL
from ..spherical import MIN_RADIUS


@njit(cache=True, nogil=True, inline="always")
def _warped(x, y, z, r, sigma):
    """The pole warp of a local point at radius ``r``: warp.plus_minus, then
    ``(2 sigma x, sigma^2 (r + y) - (r - y), 2 sigma z)`` (docs/math.md, section 3)."""
    exact = abs(y) + r
    complement = (x * x + z * z) / exact
    if y < 0.0:
        plus, minus = complement, exact
    else:
        plus, minus = exact, complement
    return 2.0 * sigma * x, (sigma * sigma) * plus - minus, 2.0 * sigma * z


@njit(cache=True, nogil=True)
def warp_batch(points, centers, rotations, sigmas, warp):
    """Per candidate (k) and vertex (n): the warped direction's ``sqrt(a^2 + b^2)``, ``b``,
    ``a`` and ``c`` (``atan2`` of the first and last pair are theta, of the middle pair phi),
    with whether a vertex is at the centre (k,) and the cap cosine (k,):
    :class:`.objective._Angles` before its two ``atan2`` (numpy's are vectorised)."""
    k, n = centers.shape[0], points.shape[0]
    across = np.empty((k, n))
    second = np.empty((k, n))
    first = np.empty((k, n))
    height = np.empty((k, n))
    at_centre = np.zeros(k, dtype=np.bool_)
    cap = np.full(k, -np.inf)
    for j in range(k):
        rotation, center, sigma = rotations[j], centers[j], sigmas[j]
        r00, r01, r02 = rotation[0, 0], rotation[0, 1], rotation[0, 2]
        r10, r11, r12 = rotation[1, 0], rotation[1, 1], rotation[1, 2]
        r20, r21, r22 = rotation[2, 0], rotation[2, 1], rotation[2, 2]
        c0, c1, c2 = center[0], center[1], center[2]
        m0 = r00 * c0 + r01 * c1 + r02 * c2
        m1 = r10 * c0 + r11 * c1 + r12 * c2
        m2 = r20 * c0 + r21 * c1 + r22 * c2
        for i in range(n):
            p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
            x = (r00 * p0 + r01 * p1 + r02 * p2) - m0
            y = (r10 * p0 + r11 * p1 + r12 * p2) - m1
            z = (r20 * p0 + r21 * p1 + r22 * p2) - m2
            r = math.sqrt(x * x + y * y + z * z)
            if r < MIN_RADIUS:
                at_centre[j] = True
                r = 1.0
            if warp:
                a, b, c = _warped(x, y, z, r, sigma)
            else:
                a, b, c = x, y, z
            across[j, i] = math.sqrt(a * a + b * b)
            second[j, i] = b
            first[j, i] = a
            height[j, i] = c
            cosine = y / r
            if cosine > cap[j]:
                cap[j] = cosine
    return across, height, second, first, at_centre, cap


@njit(cache=True, nogil=True)
def _distance(normals, offsets, center, f):
    """How far face ``f``'s plane lies ahead of ``center`` (the sign tells the side)."""
    return offsets[f] - (
        center[0] * normals[f, 0] + center[1] * normals[f, 1] + center[2] * normals[f, 2]
    )


@njit(cache=True, nogil=True)
def _ahead_wins(normals, offsets, center):
    """Whether the faces seen from the front are those ahead of ``center`` (at least as many
    as behind): the region's own winding, as validation judges it."""
    ahead = 0
    behind = 0
    for f in range(normals.shape[0]):
        distance = _distance(normals, offsets, center, f)
        if distance > 0.0:
            ahead += 1
        elif distance < 0.0:
            behind += 1
    return ahead >= behind


@njit(cache=True, nogil=True)
def _face_sums(faces, metric, area, cubed, measurable, normals, offsets, center, split, phi, s):
    """:meth:`.objective._FaceShapes.sums` for one candidate: seen area, seen layout area,
    measured area, sums of area times F and of cubed area times F / D^2, area behind."""
    m = faces.shape[1]
    total = 0.0
    for f in range(m):
        total += area[f]
    use_ahead = _ahead_wins(normals, offsets, center) if split else True
    seen_area = 0.0
    seen_layout = 0.0
    weight = 0.0
    frobenius_sum = 0.0
    inverse_sum = 0.0
    for f in range(m):
        i0, i1, i2 = faces[0, f], faces[1, f], faces[2, f]
        x1, y1 = phi[i1] - phi[i0], s[i1] - s[i0]
        x2, y2 = phi[i2] - phi[i0], s[i2] - s[i0]
        real = x1 * x2 + y1 * y2
        layout_area = abs(x1 * y2 - y1 * x2)
        frobenius = (
            metric[0, f] * (x1 * x1 + y1 * y1)
            + metric[1, f] * real
            + metric[2, f] * (x2 * x2 + y2 * y2)
        )
        measured = layout_area > DEGENERATE_RTOL * frobenius * area[f] and measurable[f]
        front = True
        if split:
            distance = _distance(normals, offsets, center, f)
            front = distance > 0.0 if use_ahead else distance < 0.0
            measured = measured and front
        if front:
            seen_area += area[f]
            seen_layout += layout_area
        if measured:
            weight += area[f]
            frobenius_sum += frobenius * area[f]
            inverse_sum += frobenius / (layout_area * layout_area) * cubed[f]
    if not split:
        seen_area = total
    return seen_area, seen_layout, weight, frobenius_sum, inverse_sum, total - seen_area


@njit(cache=True, nogil=True)
def sums_batch(faces, metric, area, cubed, measurable, normals, offsets, centers, split, phi, s):
    """(6, k) :func:`_face_sums` of every candidate, its layout points ``phi`` and ``s``
    (k, n) given: :meth:`.objective._FaceShapes.sums`."""
    k = centers.shape[0]
    sums = np.empty((6, k))
    for j in range(k):
        found = _face_sums(
            faces, metric, area, cubed, measurable, normals, offsets, centers[j], split,
            phi[j], s[j],
        )  # fmt: skip
        for t in range(6):
            sums[t, j] = found[t]
    return sums


@njit(cache=True, nogil=True)
def sums_of_plane(faces, metric, area, cubed, measurable, normals, offsets, center, phi, second):
    """(6,) :func:`_face_sums` of one candidate whose layout points are given, the faces
    seen from behind split off."""
    found = _face_sums(
        faces, metric, area, cubed, measurable, normals, offsets, center, True, phi, second
    )
    out = np.empty(6)
    for t in range(6):
        out[t] = found[t]
    return out


@njit(cache=True, nogil=True)
def energy_gradient(
    faces, metric, area, cubed, measurable, normals, offsets, center, phi, second, n,
    seen_area, seen_layout, weight, frobenius_sum, inverse_sum,
):  # fmt: skip
    """:func:`.objective._energy_gradient`: (n,) the gradient's ``dE/dphi`` and ``dE/ds``
    per vertex, as two real arrays."""
    m = faces.shape[1]
    use_ahead = _ahead_wins(normals, offsets, center)
    squared_scale = seen_area / seen_layout
    by_frobenius_sum = squared_scale / (4.0 * weight)
    by_inverse_sum = 1.0 / (4.0 * weight * squared_scale)
    by_layout_sum = -(frobenius_sum - inverse_sum / squared_scale**2) / (4.0 * weight)
    by_layout_sum *= squared_scale / seen_layout
    gx = np.zeros(n)
    gy = np.zeros(n)
    for f in range(m):
        i0, i1, i2 = faces[0, f], faces[1, f], faces[2, f]
        x1, y1 = phi[i1] - phi[i0], second[i1] - second[i0]
        x2, y2 = phi[i2] - phi[i0], second[i2] - second[i0]
        real = x1 * x2 + y1 * y2
        signed = x1 * y2 - y1 * x2
        layout_area = abs(signed)
        g22, g12, g11 = metric[0, f], metric[1, f], metric[2, f]
        frobenius = g22 * (x1 * x1 + y1 * y1) + g12 * real + g11 * (x2 * x2 + y2 * y2)
        distance = _distance(normals, offsets, center, f)
        front = distance > 0.0 if use_ahead else distance < 0.0
        measured = measurable[f] and front and layout_area > DEGENERATE_RTOL * frobenius * area[f]
        by_frobenius = 0.0
        by_area = by_layout_sum if front else 0.0
        if measured:
            safe = layout_area
            by_frobenius = area[f] * by_frobenius_sum + cubed[f] / safe**2 * by_inverse_sum
            by_area -= 2.0 * cubed[f] * frobenius / safe**3 * by_inverse_sum
        sign = 1.0 if signed > 0.0 else (-1.0 if signed < 0.0 else 0.0)
        by_signed = by_area * sign
        # first = bF (2 g22 z1 + g12 z2) + bS (y2 - i x2); second = bF (2 g11 z2 + g12 z1)
        # + bS (-y1 + i x1).
        first_x = by_frobenius * (2.0 * g22 * x1 + g12 * x2) + by_signed * y2
        first_y = by_frobenius * (2.0 * g22 * y1 + g12 * y2) - by_signed * x2
        second_x = by_frobenius * (2.0 * g11 * x2 + g12 * x1) - by_signed * y1
        second_y = by_frobenius * (2.0 * g11 * y2 + g12 * y1) + by_signed * x1
        gx[i1] += first_x
        gy[i1] += first_y
        gx[i2] += second_x
        gy[i2] += second_y
        gx[i0] -= first_x + second_x
        gy[i0] -= first_y + second_y
    return gx, gy


@njit(cache=True, nogil=True)
def _angle(p0, p1, p2, q0, q1, q2):
    """:func:`transforms.margins._angle` of two vectors."""
    c0 = p1 * q2 - p2 * q1
    c1 = p2 * q0 - p0 * q2
    c2 = p0 * q1 - p1 * q0
    return math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), p0 * q0 + p1 * q1 + p2 * q2)


@njit(cache=True, nogil=True)
def _arc_to_point(a, b, point, point_arc):
    """:func:`transforms.margins.arcs_to_point` of one arc ``a -> b`` (unit, (3,) each)."""
    a0, a1, a2 = a[0], a[1], a[2]
    b0, b1, b2 = b[0], b[1], b[2]
    p0, p1, p2 = point[0], point[1], point[2]
    n0 = a1 * b2 - a2 * b1
    n1 = a2 * b0 - a0 * b2
    n2 = a0 * b1 - a1 * b0
    length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    ends = min(_angle(a0, a1, a2, p0, p1, p2), _angle(b0, b1, b2, p0, p1, p2))
    if not length > point_arc:
        return ends
    u0, u1, u2 = n0 / length, n1 / length, n2 / length
    off_plane = u0 * p0 + u1 * p1 + u2 * p2
    i0, i1, i2 = p0 - off_plane * u0, p1 - off_plane * u1, p2 - off_plane * u2
    # a x point and point x b against the normal: the foot between a and b.
    s0 = (a1 * p2 - a2 * p1) * n0 + (a2 * p0 - a0 * p2) * n1 + (a0 * p1 - a1 * p0) * n2
    s1 = (p1 * b2 - p2 * b1) * n0 + (p2 * b0 - p0 * b2) * n1 + (p0 * b1 - p1 * b0) * n2
    if s0 >= 0 and s1 >= 0:
        to_circle = math.atan2(abs(off_plane), math.sqrt(i0 * i0 + i1 * i1 + i2 * i2))
        return min(to_circle, ends)
    return ends


@njit(cache=True, nogil=True)
def clearances(units, faces, poles, point_arc):
    """:func:`.emptycap.free_cap`'s measure of each candidate: (k,) radians from each unit
    row of ``poles`` (k, 3) to the nearest point of the region (``units`` (n, 3), ``faces``
    (m, 3)) seen from the centre, 0 when a face's spherical triangle holds it: one pass over
    the faces for every candidate's cover test (:func:`_covered`), then the uncovered ones
    measured (:func:`_nearest`)."""
    covered, least_dot = _covered(units, faces, poles)
    half_longest = 0.5 * math.acos(min(max(least_dot, -1.0), 1.0))
    free = np.zeros(poles.shape[0])
    for p in range(poles.shape[0]):
        if not covered[p]:
            free[p] = _nearest(units, faces, poles[p], half_longest, point_arc)
    return free


@njit(cache=True, nogil=True)
def _covered(units, faces, poles):
    """(k,) bool: whether a face's spherical triangle holds each of ``poles`` (the same side
    of its three great circles, and on the triangle's side of the sphere); and the least
    cosine between an edge's ends (the longest edge's)."""
    k = poles.shape[0]
    covered = np.zeros(k, dtype=np.bool_)
    least_dot = 1.0
    for f in range(faces.shape[0]):
        a, b, c = units[faces[f, 0]], units[faces[f, 1]], units[faces[f, 2]]
        least_dot = min(least_dot, a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
        least_dot = min(least_dot, b[0] * c[0] + b[1] * c[1] + b[2] * c[2])
        least_dot = min(least_dot, c[0] * a[0] + c[1] * a[1] + c[2] * a[2])
        ab = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
        bc = (b[1] * c[2] - b[2] * c[1], b[2] * c[0] - b[0] * c[2], b[0] * c[1] - b[1] * c[0])
        ca = (c[1] * a[2] - c[2] * a[1], c[2] * a[0] - c[0] * a[2], c[0] * a[1] - c[1] * a[0])
        middle = ((a[0] + b[0]) + c[0], (a[1] + b[1]) + c[1], (a[2] + b[2]) + c[2])
        for p in range(k):
            q0, q1, q2 = poles[p, 0], poles[p, 1], poles[p, 2]
            x = ab[0] * q0 + ab[1] * q1 + ab[2] * q2
            y = bc[0] * q0 + bc[1] * q1 + bc[2] * q2
            z = ca[0] * q0 + ca[1] * q1 + ca[2] * q2
            same = (x >= 0 and y >= 0 and z >= 0) or (x <= 0 and y <= 0 and z <= 0)
            facing = middle[0] * q0 + middle[1] * q1 + middle[2] * q2 > 0
            covered[p] |= same and facing and (x != 0 or y != 0 or z != 0)
    return covered, least_dot


@njit(cache=True, nogil=True)
def _nearest(units, faces, pole, half_longest, point_arc):
    """Radians from unit ``pole`` (held by no face) to the nearest vertex or edge arc. An arc
    of length L whose nearer end is d away comes no nearer than d - L / 2, so only the edges
    with an end within the nearest vertex's angle plus half the longest edge are measured."""
    cosine = units[:, 0] * pole[0] + units[:, 1] * pole[1] + units[:, 2] * pole[2]
    free = math.acos(min(max(cosine.max(), -1.0), 1.0))
    # A margin over the rounding of acos and cos.
    reach = math.cos(min(free + half_longest + 1e-9, math.pi))
    for side in range(3):
        for f in range(faces.shape[0]):
            start, end = faces[f, side], faces[f, (side + 1) % 3]
            ends = max(cosine[start], cosine[end])
            if ends < reach:
                continue
            nearest = math.acos(min(max(ends, -1.0), 1.0))
            s, e = units[start], units[end]
            length = math.acos(min(max(s[0] * e[0] + s[1] * e[1] + s[2] * e[2], -1.0), 1.0))
            if nearest - length / 2.0 < free:
                free = min(free, _arc_to_point(s, e, pole, point_arc))
    return free


@njit(cache=True, nogil=True)
def moved_gradient(
    offsets, rotation, local, r, warped, theta, by_phi, by_second,
    turns, shifts, log_sigma, sigma, sigma_moves, mercator, margin,
):  # fmt: skip
    """:meth:`.objective._Warped.moves` contracted with the energy's gradient per vertex
    (``by_phi``, ``by_second``): the energy's gradient along each of ``d`` motions (d,) and
    the cap cosine's (d,). ``turns`` (d, 3, 3): the rotation's derivatives; ``shifts``
    (d, 3): the centre's, scaled as ``offsets``; ``log_sigma`` (d,)."""
    d, n = log_sigma.shape[0], offsets.shape[0]
    gradient = np.zeros(d)
    cap = np.zeros(d)
    top = 0
    for i in range(n):
        if local[1, i] / r[i] > local[1, top] / r[top]:
            top = i
    for k in range(d):
        t = turns[k]
        s0 = rotation[0, 0] * shifts[k, 0] + rotation[0, 1] * shifts[k, 1]
        s0 += rotation[0, 2] * shifts[k, 2]
        s1 = rotation[1, 0] * shifts[k, 0] + rotation[1, 1] * shifts[k, 1]
        s1 += rotation[1, 2] * shifts[k, 2]
        s2 = rotation[2, 0] * shifts[k, 0] + rotation[2, 1] * shifts[k, 1]
        s2 += rotation[2, 2] * shifts[k, 2]
        dsigma = sigma_moves * sigma * log_sigma[k]
        total = 0.0
        for i in range(n):
            o0, o1, o2 = offsets[i, 0], offsets[i, 1], offsets[i, 2]
            dx = (t[0, 0] * o0 + t[0, 1] * o1 + t[0, 2] * o2) - s0
            dy = (t[1, 0] * o0 + t[1, 1] * o1 + t[1, 2] * o2) - s1
            dz = (t[2, 0] * o0 + t[2, 1] * o1 + t[2, 2] * o2) - s2
            x, y, z, ri = local[0, i], local[1, i], local[2, i], r[i]
            dr = (x * dx + y * dy + z * dz) / ri
            if i == top:
                cap[k] = (dy - (y / ri) * dr) / ri
            a, b, c = warped[0, i], warped[1, i], warped[2, i]
            da = 2.0 * (sigma * dx + x * dsigma)
            dc = 2.0 * (sigma * dz + z * dsigma)
            db = (
                (sigma * sigma - 1.0) * dr
                + (sigma * sigma + 1.0) * dy
                + 2.0 * sigma * (ri + y) * dsigma
            )
            across = a * a + b * b
            rho = math.sqrt(across)
            dphi = (a * db - b * da) / across
            drho = (a * da + b * db) / rho
            dtheta = (c * drho - rho * dc) / (across + c * c)
            if mercator:
                if theta[i] > margin and theta[i] < math.pi - margin:
                    dtheta = dtheta / math.sin(theta[i])
                else:
                    dtheta = 0.0
            total += dphi * by_phi[i] + dtheta * by_second[i]
        gradient[k] = total
    return gradient, cap


@njit(cache=True, nogil=True)
def warp_one(offsets, rotation, sigma, mercator, margin):
    """:class:`.objective._Warped` of one candidate: the local rows (3, n), the distances
    (n,), the warped directions times ``r`` (3, n), theta, phi and the measured second
    coordinate (n,), whether a vertex is at the centre and the cap cosine."""
    n = offsets.shape[0]
    local = np.empty((3, n))
    r = np.empty(n)
    warped = np.empty((3, n))
    theta = np.empty(n)
    phi = np.empty(n)
    second = np.empty(n)
    at_centre = False
    cap = -np.inf
    for i in range(n):
        o0, o1, o2 = offsets[i, 0], offsets[i, 1], offsets[i, 2]
        x = rotation[0, 0] * o0 + rotation[0, 1] * o1 + rotation[0, 2] * o2
        y = rotation[1, 0] * o0 + rotation[1, 1] * o1 + rotation[1, 2] * o2
        z = rotation[2, 0] * o0 + rotation[2, 1] * o1 + rotation[2, 2] * o2
        local[0, i], local[1, i], local[2, i] = x, y, z
        ri = math.sqrt(x * x + y * y + z * z)
        if ri < MIN_RADIUS:
            at_centre = True
            ri = 1.0
        r[i] = ri
        a, b, c = _warped(x, y, z, ri, sigma)
        warped[0, i], warped[1, i], warped[2, i] = a, b, c
        t = math.atan2(math.sqrt(a * a + b * b), c)
        theta[i] = t
        angle = math.atan2(b, a)
        phi[i] = math.pi if angle == -math.pi else angle
        if mercator:
            kept = min(max(t, margin), math.pi - margin)
            second[i] = math.log(math.tan(0.5 * kept))
        else:
            second[i] = t
        cap = max(cap, y / ri)
    return local, r, warped, theta, phi, second, at_centre, cap
