"""The ten landmark types, their reusable pieces, props and trees, each drawn from a seeded generator into a
:class:`_Builder` (local frame: front faces +z, base on y = 0)."""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from .geometry import (_arch_crown, _arch_profile, _box, _cat, _ellipsoid, _extrude, _extrude_x, _frustum,
                       _gable_profile, _Geom, _pyramid, _ry, _rz, _stairs_profile, _xf)
from .materials import _Palette, Rng


class _Builder:
    """Collects geometry per part name, each part tied to a palette slot."""

    def __init__(self, palette: _Palette, prefix: str) -> None:
        self.palette, self.prefix = palette, prefix
        self.geoms: dict[str, list[_Geom]] = {}
        self.slots: dict[str, str] = {}

    def add(self, part: str, geom: _Geom, slot: str) -> None:
        name = f"{self.prefix}_{part}"
        if name in self.slots and self.slots[name] != slot:
            raise ValueError(f"part {name} already uses slot {self.slots[name]}, not {slot}")
        self.palette.get(slot)
        self.slots[name] = slot
        self.geoms.setdefault(name, []).append(geom)

    def merged(self) -> dict[str, _Geom]:
        return {k: _cat(v) for k, v in self.geoms.items()}


def _u(r: Rng, a: float, b: float) -> float:
    return float(r.uniform(a, b))


def _ri(r: Rng, a: int, b: int) -> int:
    """Integer in [a, b] inclusive."""
    return int(r.integers(a, b + 1))


def _pick(r: Rng, options):
    return options[int(r.integers(len(options)))]


# ---- reusable pieces ------------------------------------------------------------------


def _stepped_base(b: _Builder, half_x: float, half_z: float, n: int, rise: float, run: float,
                  part: str = "steps", slot: str = "paving") -> float:
    """Stacked boxes, each ``run`` smaller than the one below; returns the top height."""
    for k in range(n):
        g = (n - 1 - k) * run
        b.add(part, _box((-half_x - g, k * rise, -half_z - g), (half_x + g, (k + 1) * rise, half_z + g)), slot)
    return n * rise


def _column(b: _Builder, x: float, z: float, y0: float, height: float, radius: float,
            part: str = "columns", slot: str = "marble", seg: int = 14) -> None:
    """Square base, slightly tapered smooth shaft, square capital."""
    base_h, cap_h = 0.08 * height, 0.07 * height
    w = 1.25 * radius
    b.add(part, _box((x - w, y0, z - w), (x + w, y0 + base_h, z + w)), slot)
    shaft = _frustum(radius, 0.86 * radius, y0 + base_h, y0 + height - cap_h, seg, smooth=True)
    b.add(part, _xf(shaft, None, (x, 0.0, z)), slot)
    b.add(part, _box((x - w, y0 + height - cap_h, z - w), (x + w, y0 + height, z + w)), slot)


def _figure(h: float) -> list[_Geom]:
    """A standing figure of height ``h`` on y = 0 (robe, torso, shoulders, head, arms)."""
    r = 0.16 * h
    gs = [
        _frustum(r, 0.7 * r, 0.0, 0.5 * h, 12),
        _frustum(0.7 * r, 0.62 * r, 0.5 * h, 0.8 * h, 12),
        _box((-0.2 * h, 0.74 * h, -0.07 * h), (0.2 * h, 0.84 * h, 0.07 * h)),
        _ellipsoid((0.07 * h, 0.085 * h, 0.075 * h), (0.0, 0.92 * h, 0.0), 6, 10),
        _box((-0.2 * h, 0.42 * h, -0.05 * h), (-0.12 * h, 0.8 * h, 0.05 * h)),
        # raised arm: a box tilted outwards about the figure's depth axis
        _xf(_box((-0.04 * h, 0.0, -0.04 * h), (0.04 * h, 0.36 * h, 0.04 * h)), _rz(-0.6), (0.16 * h, 0.78 * h, 0.0)),
    ]
    return gs


def _statue_on_pedestal(b: _Builder, r: Rng, x: float, z: float, y0: float, scale: float,
                        part: str = "statue", ped_part: str = "pedestal") -> float:
    """Pedestal (plinth, die, cornice) with a figure, obelisk or sphere; returns the top height."""
    pw, ph = 0.5 * scale * _u(r, 0.8, 1.3), scale * _u(r, 0.9, 1.6)
    b.add(ped_part, _box((x - 1.2 * pw, y0, z - 1.2 * pw), (x + 1.2 * pw, y0 + 0.15 * ph, z + 1.2 * pw)), "trim")
    b.add(ped_part, _box((x - pw, y0 + 0.15 * ph, z - pw), (x + pw, y0 + 0.88 * ph, z + pw)), "trim")
    b.add(ped_part, _box((x - 1.15 * pw, y0 + 0.88 * ph, z - 1.15 * pw), (x + 1.15 * pw, y0 + ph, z + 1.15 * pw)),
          "trim")
    top = y0 + ph
    kind = _pick(r, ("figure", "figure", "obelisk", "sphere"))
    if kind == "figure":
        fh = scale * _u(r, 1.4, 2.2)
        yaw = _u(r, -0.5, 0.5)
        for g in _figure(fh):
            b.add(part, _xf(g, _ry(yaw), (x, top, z)), "statue")
        return top + fh
    if kind == "obelisk":
        oh = scale * _u(r, 2.5, 4.5)
        ob = _frustum(0.8 * pw * math.sqrt(2), 0.5 * pw * math.sqrt(2), 0.0, oh, 4, smooth=False, phase=np.pi / 4)
        tip = _frustum(0.5 * pw * math.sqrt(2), 0.0, oh, oh + 0.6 * pw, 4, smooth=False, phase=np.pi / 4)
        b.add(part, _xf(ob, None, (x, top, z)), "statue")
        b.add(part, _xf(tip, None, (x, top, z)), "statue")
        return top + oh + 0.6 * pw
    rad = 0.9 * pw
    b.add(part, _ellipsoid((rad, rad, rad), (x, top + rad, z), 8, 14), "statue")
    return top + 2 * rad


def _windows_on_block(b: _Builder, cx: float, cz: float, w: float, d: float, rows: list[float],
                      win_w: float, win_h: float, spacing: float, skip: Callable[[float, float], bool],
                      door_gap: float = 0.0) -> None:
    """Dark window slabs (protruding 4 cm) on the four faces of a box block.

    ``rows`` are window centre heights; ``skip(x, z)`` hides windows whose centre lies
    inside another block; ``door_gap`` clears the middle of the front ground floor.
    """
    out = 0.04
    for axis, sign in ((2, 1), (2, -1), (0, 1), (0, -1)):
        length = w if axis == 2 else d
        n = max(1, int((length - 1.0) // spacing))
        hs = (np.arange(n) + 0.5) * length / n - length / 2
        for ri_, yc in enumerate(rows):
            for hpos in hs:
                if axis == 2 and sign > 0 and ri_ == 0 and abs(hpos) < door_gap:
                    continue
                if axis == 2:
                    x, z = cx + hpos, cz + sign * d / 2
                    lo = (x - win_w / 2, yc - win_h / 2, z - 0.1 if sign > 0 else z - out)
                    hi = (x + win_w / 2, yc + win_h / 2, z + out if sign > 0 else z + 0.1)
                    cxz = (x, cz + sign * (d / 2 + 0.5))
                else:
                    x, z = cx + sign * w / 2, cz + hpos
                    lo = (x - 0.1 if sign > 0 else x - out, yc - win_h / 2, z - win_w / 2)
                    hi = (x + out if sign > 0 else x + 0.1, yc + win_h / 2, z + win_w / 2)
                    cxz = (cx + sign * (w / 2 + 0.5), z)
                if skip(*cxz):
                    continue
                b.add("windows", _box(lo, hi), "window")


def _roof(b: _Builder, kind: str, cx: float, cz: float, w: float, d: float, y0: float, r: Rng) -> float:
    """A roof over the block ``[cx -+ w/2] x [cz -+ d/2]`` starting at ``y0``; returns its top."""
    oh = _u(r, 0.2, 0.6)
    if kind == "flat":
        b.add("cornice", _box((cx - w / 2 - oh, y0, cz - d / 2 - oh), (cx + w / 2 + oh, y0 + 0.5, cz + d / 2 + oh)),
              "trim")
        b.add("cornice", _box((cx - w / 2, y0 + 0.5, cz - d / 2), (cx + w / 2, y0 + 1.1, cz + d / 2)), "trim")
        return y0 + 1.1
    pitch = math.radians(_u(r, 22.0, 40.0))
    if kind == "gable":
        if w >= d:  # ridge along x
            hs = d / 2 + oh
            rise = hs * math.tan(pitch)
            g = _extrude_x(_gable_profile(hs, rise), -w / 2 - oh, w / 2 + oh)
        else:
            hs = w / 2 + oh
            rise = hs * math.tan(pitch)
            g = _extrude(_gable_profile(hs, rise), -d / 2 - oh, d / 2 + oh)
        b.add("roof", _xf(g, None, (cx, y0, cz)), "roof")
        return y0 + rise
    top_frac = 0.0 if kind == "hip" else _u(r, 0.45, 0.7)  # mansard: truncated
    rise = (min(w, d) / 2 + oh) * math.tan(pitch) * (1.0 if kind == "hip" else 1.6)
    b.add("roof", _xf(_pyramid(w / 2 + oh, d / 2 + oh, 0.0, rise, top_frac), None, (cx, y0, cz)), "roof")
    return y0 + rise


# ---- landmark types (local frame: front faces +z, base on y = 0) -----------------------


def _build_building(r: Rng, b: _Builder) -> dict[str, Any]:
    storeys = _ri(r, 1, 4)
    sh = _u(r, 3.0, 4.2)
    W, D = _u(r, 8.0, 22.0), _u(r, 6.0, 14.0)
    H = storeys * sh
    blocks = [(0.0, 0.0, W, D, storeys)]
    wings = _pick(r, ("none", "side", "both", "back"))
    if wings in ("side", "both"):
        w2, d2 = W * _u(r, 0.3, 0.6), D * _u(r, 0.5, 0.9)
        st2 = max(1, storeys - _ri(r, 0, 2))
        sides = (1, -1) if wings == "both" else (_pick(r, (1, -1)),)
        for s in sides:
            blocks.append((s * (W / 2 + w2 / 2 - 0.3), -(D - d2) / 2, w2, d2, st2))
    elif wings == "back":
        w2, d2 = W * _u(r, 0.3, 0.7), D * _u(r, 0.4, 1.0)
        blocks.append((0.0, -(D / 2 + d2 / 2 - 0.3), w2, d2, max(1, storeys - _ri(r, 0, 1))))
    roof = _pick(r, ("gable", "gable", "hip", "mansard", "flat"))
    win_w, win_h = _u(r, 0.8, 1.5), min(_u(r, 1.2, 2.1), 0.6 * sh)
    spacing = _u(r, 2.4, 4.0)
    plinth_h = _u(r, 0.4, 1.0)

    def inside_other(k: int) -> Callable[[float, float], bool]:
        def f(x: float, z: float) -> bool:
            for j, (cx, cz, w, d, _) in enumerate(blocks):
                if j != k and abs(x - cx) < w / 2 and abs(z - cz) < d / 2:
                    return True
            return False
        return f

    door_w = _u(r, 1.2, 2.4)
    for k, (cx, cz, w, d, st) in enumerate(blocks):
        h = st * sh
        b.add("walls", _box((cx - w / 2, 0.0, cz - d / 2), (cx + w / 2, h, cz + d / 2)), "walls")
        b.add("plinth", _box((cx - w / 2 - 0.12, 0.0, cz - d / 2 - 0.12),
                             (cx + w / 2 + 0.12, plinth_h, cz + d / 2 + 0.12)),
              "trim")
        rows = [i * sh + 0.55 * sh for i in range(st)]
        _windows_on_block(b, cx, cz, w, d, rows, win_w, win_h, spacing, inside_other(k),
                          door_gap=door_w if k == 0 else 0.0)
        _roof(b, roof, cx, cz, w, d, h, r)
    b.add("door", _box((-door_w / 2, 0.0, D / 2 - 0.1), (door_w / 2, min(0.8 * sh, 3.0), D / 2 + 0.06)), "window")
    tower = r.random() < 0.25
    if tower:  # small clock/bell tower rising from the front of the main block
        tw = _u(r, 2.5, 4.0)
        th = H + _u(r, 3.0, 8.0)
        z0 = D / 2 - tw
        b.add("tower", _box((-tw / 2, 0.0, z0 - tw / 2), (tw / 2, th, z0 + tw / 2)), "trim")
        b.add("roof", _pyramid(tw / 2 + 0.3, tw / 2 + 0.3, th, _u(r, 1.5, 4.0)), "roof")
    return {"storeys": storeys, "width": W, "depth": D, "wings": wings, "roof": roof, "tower": tower}


def _build_tower(r: Rng, b: _Builder) -> dict[str, Any]:
    plan = _pick(r, ("square", "octagon", "round"))
    w = _u(r, 4.0, 9.0)
    H = _u(r, 15.0, 40.0)
    tiers = _ri(r, 2, 4)
    heights = H * r.dirichlet(np.full(tiers, 3.0))
    shrink = _u(r, 0.75, 0.95)
    top = _pick(r, ("spire", "crenellations", "dome", "belfry"))
    y, width = 0.0, w

    def body(hw: float, y0: float, y1: float) -> _Geom:
        if plan == "square":
            return _box((-hw, y0, -hw), (hw, y1, hw))
        if plan == "octagon":
            return _frustum(hw / math.cos(np.pi / 8), hw / math.cos(np.pi / 8), y0, y1, 8, smooth=False,
                            phase=np.pi / 8)
        return _frustum(hw, hw, y0, y1, 24, smooth=True)

    for k, th in enumerate(heights):
        hw = width / 2
        b.add("body", body(hw, y, y + th), "masonry")
        # slit windows half-way up the tier on four sides
        ww, wh = 0.5 + 0.1 * width, min(0.4 * th, _u(r, 1.2, 2.5))
        for a in range(4):
            gw = _box((-ww / 2, y + 0.5 * th - wh / 2, hw - 0.1), (ww / 2, y + 0.5 * th + wh / 2, hw + 0.05))
            b.add("windows", _xf(gw, _ry(a * np.pi / 2)), "window")
        y += th
        if k < tiers - 1 or top != "belfry":
            c = 1.12 * hw + 0.15
            b.add("cornice", body(c, y - 0.05, y + 0.35), "trim")
            y += 0.35
        width *= shrink if k < tiers - 1 else 1.0
    hw = width / 2
    if top == "spire":
        sh = _u(r, 0.8, 2.5) * width
        g = (_pyramid(hw + 0.2, hw + 0.2, y, sh) if plan == "square"
             else _frustum((hw + 0.2) / math.cos(np.pi / 8), 0.0, y, y + sh, 8, smooth=False, phase=np.pi / 8)
             if plan == "octagon" else _frustum(hw + 0.2, 0.0, y, y + sh, 24, smooth=True))
        b.add("roof", g, "roof")
    elif top == "dome":
        b.add("roof", _ellipsoid((hw, hw * _u(r, 0.8, 1.4), hw), (0.0, y, 0.0), 6, 20, hemi=True), "roof")
    elif top == "crenellations":
        n = max(2, int(round(2 * hw / 1.2)))
        mw = 2 * hw / (2 * n - 1)
        for a in range(4):
            for i in range(n):
                x0 = -hw + 2 * i * mw
                g = _box((x0, y, hw - 0.5), (x0 + mw, y + 1.0, hw))
                b.add("merlons", _xf(g, _ry(a * np.pi / 2)), "masonry")
    else:  # belfry: four corner piers, a slab and a pyramid
        ph = _u(r, 2.5, 4.5)
        pw = 0.22 * width
        for sx in (-1, 1):
            for sz in (-1, 1):
                b.add("belfry", _box((sx * hw - (pw if sx > 0 else 0), y, sz * hw - (pw if sz > 0 else 0)),
                                     (sx * hw + (pw if sx < 0 else 0), y + ph, sz * hw + (pw if sz < 0 else 0))),
                      "masonry")
        b.add("cornice", _box((-hw - 0.2, y + ph, -hw - 0.2), (hw + 0.2, y + ph + 0.4, hw + 0.2)), "trim")
        b.add("roof", _pyramid(hw + 0.3, hw + 0.3, y + ph + 0.4, _u(r, 0.8, 1.8) * width), "roof")
    annex = r.random() < 0.35
    if annex:
        aw, ad, ah = _u(r, 5.0, 12.0), _u(r, 4.0, 8.0), _u(r, 3.0, 6.0)
        ax = w / 2 + aw / 2 - 0.2
        b.add("annex", _box((ax - aw / 2, 0.0, -ad / 2), (ax + aw / 2, ah, ad / 2)), "walls")
        _roof(b, "gable", ax, 0.0, aw, ad, ah, r)
    return {"plan": plan, "width": w, "height": H, "tiers": tiers, "top": top, "annex": annex}


def _build_temple(r: Rng, b: _Builder) -> dict[str, Any]:
    n_front = _pick(r, (4, 6, 6, 8))
    peripteral = r.random() < 0.5
    Hc = _u(r, 5.0, 10.0)
    rad = Hc / _u(r, 8.0, 11.0)
    sp = rad * _u(r, 4.0, 5.5)
    W = (n_front - 1) * sp
    n_side = (n_front + _ri(r, 1, 4)) if peripteral else _ri(r, 2, 3)
    D = (n_side - 1) * sp
    steps = _ri(r, 2, 4)
    rise = _u(r, 0.25, 0.45)
    y0 = _stepped_base(b, W / 2 + 2 * rad, D / 2 + 2 * rad, steps, rise, _u(r, 0.35, 0.6), slot="marble",
                       part="stylobate")
    xs = np.linspace(-W / 2, W / 2, n_front)
    zs = np.linspace(-D / 2, D / 2, n_side)
    for i, x in enumerate(xs):
        for j, z in enumerate(zs):
            on_ring = i in (0, n_front - 1) or j in (0, n_side - 1)
            if (peripteral and on_ring) or (not peripteral and j == n_side - 1):
                _column(b, float(x), float(z), y0, Hc, rad)
    ent_h = 0.2 * Hc
    y1 = y0 + Hc
    m = 1.3 * rad
    b.add("entablature", _box((-W / 2 - m, y1, -D / 2 - m), (W / 2 + m, y1 + ent_h, D / 2 + m)), "marble")
    cella_d = D - (sp if not peripteral else 2 * sp)
    if cella_d > 1.0:
        cz1 = D / 2 - (sp if not peripteral else sp)
        cw = W - (0 if not peripteral else 2 * sp) - 2 * m
        if cw > 1.0:
            b.add("cella", _box((-cw / 2, y0, cz1 - cella_d), (cw / 2, y1, cz1)), "walls")
    pediment = r.random() < 0.75
    top = y1 + ent_h
    if pediment:
        hs = W / 2 + m + 0.2
        rise_p = hs * math.tan(math.radians(_u(r, 12.0, 20.0)))
        g = _extrude(_gable_profile(hs, rise_p), -D / 2 - m - 0.2, D / 2 + m + 0.2)
        b.add("pediment", _xf(g, None, (0.0, top, 0.0)), "marble")
        top += rise_p
    else:
        b.add("entablature", _box((-W / 2 - m + 0.3, top, -D / 2 - m + 0.3),
                                  (W / 2 + m - 0.3, top + 0.8, D / 2 + m - 0.3)),
              "marble")
    return {"columns_front": n_front, "columns_side": n_side, "peripteral": peripteral, "column_height": Hc,
            "pediment": pediment}


def _build_colonnade(r: Rng, b: _Builder) -> dict[str, Any]:
    curved = r.random() < 0.45
    Hc = _u(r, 4.5, 9.0)
    rad = Hc / _u(r, 8.0, 11.0)
    rows = _ri(r, 1, 2)
    ent_h = 0.18 * Hc
    if not curved:
        n = _ri(r, 7, 14)
        sp = rad * _u(r, 4.0, 6.0)
        L = (n - 1) * sp
        depth = (rows - 1) * sp + 4 * rad
        y0 = _stepped_base(b, L / 2 + 2 * rad, depth / 2 + 1.0, _ri(r, 1, 3), 0.3, 0.45, part="steps")
        for k in range(rows):
            z = depth / 2 - 2 * rad - k * sp
            for x in np.linspace(-L / 2, L / 2, n):
                _column(b, float(x), z, y0, Hc, rad)
        b.add("entablature", _box((-L / 2 - 1.3 * rad, y0 + Hc, -depth / 2 - 0.5),
                                  (L / 2 + 1.3 * rad, y0 + Hc + ent_h, depth / 2)), "marble")
        back = r.random() < 0.6
        if back:
            b.add("back_wall", _box((-L / 2 - 1.3 * rad, y0, -depth / 2 - 0.5 - 0.8),
                                    (L / 2 + 1.3 * rad, y0 + Hc + ent_h, -depth / 2 - 0.5)), "walls")
            rz = -depth / 2 - 1.3
            g = _extrude_x(np.array([(rz, 0.0), (depth / 2 + 0.6, 0.0), (rz, _u(r, 1.0, 2.5))]),
                           -L / 2 - 1.6 * rad, L / 2 + 1.6 * rad)
            b.add("roof", _xf(g, None, (0.0, y0 + Hc + ent_h, 0.0)), "roof")
        return {"curved": False, "columns": n, "rows": rows, "length": L, "back_wall": back}
    Rc = _u(r, 10.0, 24.0)
    span = math.radians(_u(r, 70.0, 160.0))
    n = max(5, int(span * Rc / (rad * _u(r, 4.0, 6.0))) + 1)
    angles = np.linspace(-span / 2, span / 2, n)
    y0 = 0.4
    # Curved paving: wedge boxes under each bay, then columns on arcs, entablature chords.
    for k in range(rows):
        Rk = Rc + k * rad * 5.0
        pts = [(Rk * math.sin(a), -Rc + Rk * math.cos(a)) for a in angles]  # arc centred at (0, -Rc): apex at z=0
        for x, z in pts:
            _column(b, x, z, y0, Hc, rad)
        for a0, a1 in zip(angles[:-1], angles[1:]):
            am = 0.5 * (a0 + a1)
            chord = 2 * Rk * math.sin(0.5 * (a1 - a0)) + 2.2 * rad
            c = (Rk * math.cos(0.5 * (a1 - a0))) * np.array([math.sin(am), 0.0, math.cos(am)]) + (0.0, 0.0, -Rc)
            ent = _box((-chord / 2, y0 + Hc, -1.3 * rad), (chord / 2, y0 + Hc + ent_h, 1.3 * rad))
            b.add("entablature", _xf(ent, _ry(am), c), "marble")
            base = _box((-chord / 2, 0.0, -2.0 * rad), (chord / 2, y0, 2.0 * rad))
            b.add("steps", _xf(base, _ry(am), c), "paving")
    return {"curved": True, "columns": n, "rows": rows, "radius": Rc, "span_deg": math.degrees(span)}


def _build_arch(r: Rng, b: _Builder) -> dict[str, Any]:
    W = _u(r, 8.0, 20.0)
    D = _u(r, 3.0, 7.0)
    H = _u(r, 8.0, 18.0)
    shape = _pick(r, ("round", "round", "pointed"))
    triple = r.random() < 0.5 and W > 11
    wc = W * _u(r, 0.3, 0.42)
    hs = H * _u(r, 0.35, 0.5)
    openings = [(0.0, wc, hs, shape)]
    if triple:
        ws = wc * _u(r, 0.4, 0.55)
        xs = 0.5 * (wc / 2 + W / 2)
        openings += [(-xs, ws, hs * 0.6, shape), (xs, ws, hs * 0.6, shape)]
    crown = max(_arch_crown(w, h, s) for _, w, h, s in openings)
    H = max(H, crown + 1.5)
    b.add("body", _extrude(_arch_profile(W, H, openings), -D / 2, D / 2), "masonry")
    b.add("cornice", _box((-W / 2 - 0.3, H, -D / 2 - 0.3), (W / 2 + 0.3, H + 0.5, D / 2 + 0.3)), "trim")
    attic_h = _u(r, 0.15, 0.3) * H
    b.add("attic", _box((-W / 2 + 0.2, H + 0.5, -D / 2 + 0.2), (W / 2 - 0.2, H + 0.5 + attic_h, D / 2 - 0.2)),
          "masonry")
    columns = r.random() < 0.5
    if columns:
        rad = min(0.35, 0.06 * W)
        piers = [-W / 2 + 0.5 * (W / 2 - wc / 2), W / 2 - 0.5 * (W / 2 - wc / 2)] if not triple else \
            [-W / 2 + 0.6 * rad + 0.3, -wc / 2 - 0.6 * rad - 0.2, wc / 2 + 0.6 * rad + 0.2, W / 2 - 0.6 * rad - 0.3]
        for x in piers:
            for z in (D / 2 + 1.1 * rad, -D / 2 - 1.1 * rad):
                _column(b, float(x), z, 0.0, H, rad, slot="trim")
    statue = r.random() < 0.4
    if statue:
        top = H + 0.5 + attic_h
        for g in _figure(_u(r, 2.5, 4.0)):
            b.add("statue", _xf(g, None, (0.0, top, 0.0)), "statue")
    return {"width": W, "depth": D, "height": H, "arch": shape, "openings": len(openings), "columns": columns,
            "statue": statue}


def _build_wall(r: Rng, b: _Builder) -> dict[str, Any]:
    L = _u(r, 25.0, 50.0)
    T = _u(r, 2.0, 4.0)
    H = _u(r, 6.0, 12.0)
    shape = _pick(r, ("round", "pointed"))
    gw = _u(r, 3.0, 5.5)
    hs = min(_u(r, 2.5, 4.5), H - _arch_crown(gw, 0.0, shape) - 1.0)
    hs = max(hs, 1.0)
    H = max(H, _arch_crown(gw, hs, shape) + 1.5)
    b.add("wall", _extrude(_arch_profile(L, H, [(0.0, gw, hs, shape)]), -T / 2, T / 2), "masonry")
    # Merlons along the front edge.
    mw = _u(r, 0.8, 1.3)
    n = int(L / (2 * mw))
    for i in range(n):
        x0 = -L / 2 + 2 * i * mw + 0.5 * mw
        b.add("merlons", _box((x0, H, T / 2 - 0.5), (x0 + mw, H + 1.0, T / 2)), "masonry")
    towers = _pick(r, ("round", "square"))
    tr = _u(r, 2.2, 3.5)
    th = H + _u(r, 3.0, 8.0)
    xs = [-(gw / 2 + tr + 1.0), gw / 2 + tr + 1.0]
    ends = r.random() < 0.5
    if ends:
        xs += [-L / 2, L / 2]
    for x in xs:
        g = (_frustum(tr, tr, 0.0, th, 20) if towers == "round" else _box((-tr, 0.0, -tr), (tr, th, tr)))
        b.add("towers", _xf(g, None, (x, 0.0, 0.4)), "masonry")
        cap = (_frustum(tr + 0.35, tr + 0.35, th, th + 0.6, 20) if towers == "round"
               else _box((-tr - 0.35, th, -tr - 0.35), (tr + 0.35, th + 0.6, tr + 0.35)))
        b.add("cornice", _xf(cap, None, (x, 0.0, 0.4)), "trim")
        if r.random() < 0.5:
            roof = (_frustum(tr + 0.35, 0.0, th + 0.6, th + 0.6 + _u(r, 2.0, 5.0), 20) if towers == "round"
                    else _pyramid(tr + 0.35, tr + 0.35, th + 0.6, _u(r, 2.0, 5.0)))
            b.add("roof", _xf(roof, None, (x, 0.0, 0.4)), "roof")
        for a in range(4):  # arrow slits
            g = _box((-0.25, 0.55 * th, tr - 0.15), (0.25, 0.55 * th + 1.4, tr + 0.05))
            b.add("windows", _xf(g, _ry(a * np.pi / 2 + np.pi / 4 * (towers == "round")), (x, 0.0, 0.4)), "window")
    return {"length": L, "thickness": T, "height": H, "gate": shape, "towers": towers, "end_towers": ends}


def _build_monument(r: Rng, b: _Builder) -> dict[str, Any]:
    base = _u(r, 3.0, 7.0)
    steps = _ri(r, 2, 6)
    y0 = _stepped_base(b, base / 2, base / 2, steps, _u(r, 0.2, 0.4), _u(r, 0.3, 0.6), part="steps")
    top_kind = _pick(r, ("statue", "obelisk", "column", "group"))
    if top_kind == "statue":
        # Pedestal half-width is at most 0.78 x scale: keep it on the top step (base / 2).
        top = _statue_on_pedestal(b, r, 0.0, 0.0, y0, base * _u(r, 0.4, 0.58))
    elif top_kind == "obelisk":
        pw = base * 0.3
        ph = _u(r, 1.5, 3.0)
        b.add("pedestal", _box((-pw, y0, -pw), (pw, y0 + ph, pw)), "trim")
        oh = _u(r, 8.0, 20.0)
        ob = _frustum(0.75 * pw * math.sqrt(2), 0.45 * pw * math.sqrt(2), y0 + ph, y0 + ph + oh, 4, smooth=False,
                      phase=np.pi / 4)
        tip = _frustum(0.45 * pw * math.sqrt(2), 0.0, y0 + ph + oh, y0 + ph + oh + pw, 4, smooth=False, phase=np.pi / 4)
        b.add("obelisk", _cat([ob, tip]), "masonry")
        top = y0 + ph + oh + pw
    elif top_kind == "column":
        pw = base * 0.28
        ph = _u(r, 2.0, 4.0)
        b.add("pedestal", _box((-pw, y0, -pw), (pw, y0 + ph, pw)), "trim")
        ch = _u(r, 10.0, 25.0)
        _column(b, 0.0, 0.0, y0 + ph, ch, 0.75 * pw, part="column", slot="masonry", seg=18)
        top = y0 + ph + ch
        for g in _figure(_u(r, 2.0, 3.5)):
            b.add("statue", _xf(g, _ry(_u(r, -0.5, 0.5)), (0.0, top, 0.0)), "statue")
        top += 3.5
    else:  # group: a central figure flanked by smaller pedestals
        top = _statue_on_pedestal(b, r, 0.0, 0.0, y0, base * 0.28)
        for s in (-1, 1):  # side pedestals: within the top step, clear of the central one
            _statue_on_pedestal(b, r, s * base * 0.35, base * 0.35, y0, base * 0.16)
    return {"base": base, "steps": steps, "top": top_kind, "height": top}


def _build_rotunda(r: Rng, b: _Builder) -> dict[str, Any]:
    R = _u(r, 5.0, 12.0)
    Hd = _u(r, 5.0, 12.0)
    extra = _pick(r, ("none", "portico", "ring"))
    ring_rad = 0.09 * Hd
    ring_r = R + 4.5 * ring_rad
    # The stepped base carries the ring colonnade too, so no column overhangs a step.
    half = (ring_r + 1.5 * ring_rad + 0.5) if extra == "ring" else R + 1.0
    y0 = _stepped_base(b, half, half, _ri(r, 1, 3), 0.35, 0.5, part="steps") if r.random() < 0.5 else 0.0
    b.add("drum", _frustum(R, R, y0, y0 + Hd, 32), "walls")
    b.add("cornice", _frustum(R + 0.4, R + 0.4, y0 + Hd, y0 + Hd + 0.6, 32), "trim")
    n_win = _ri(r, 6, 12)
    wh = min(0.35 * Hd, _u(r, 1.5, 3.0))
    for k in range(n_win):
        g = _box((-0.6, y0 + 0.55 * Hd - wh / 2, R - 0.2), (0.6, y0 + 0.55 * Hd + wh / 2, R + 0.05))
        b.add("windows", _xf(g, _ry(2 * np.pi * (k + 0.5) / n_win)), "window")
    dome = _pick(r, ("dome", "dome", "cone"))
    yd = y0 + Hd + 0.6
    if dome == "dome":
        b.add("dome", _ellipsoid((R, R * _u(r, 0.6, 1.2), R), (0.0, yd, 0.0), 8, 32, hemi=True), "roof")
        top = yd + R
        if r.random() < 0.5:  # lantern
            lr = 0.15 * R
            b.add("lantern", _frustum(lr, lr, top - 0.3 * R, top + 0.2 * R, 16), "trim")
            b.add("dome", _ellipsoid((1.2 * lr,) * 3, (0.0, top + 0.2 * R, 0.0), 6, 16, hemi=True), "roof")
    else:
        b.add("dome", _frustum(R + 0.5, 0.0, yd, yd + R * _u(r, 0.5, 1.0), 32), "roof")
    if extra == "portico":
        n = _pick(r, (4, 6))
        Hc = 0.85 * Hd
        rad = Hc / 10
        sp = min(2 * R * 0.8 / (n - 1), rad * 5.5)
        W = (n - 1) * sp
        zc = R + 2.5 * rad + sp
        pf = max(y0, 0.3)  # the portico's own floor, level with the base top
        b.add("portico_floor", _box((-W / 2 - 1.0, 0.0, R * 0.5), (W / 2 + 1.0, pf, zc + 1.5)), "paving")
        for x in np.linspace(-W / 2, W / 2, n):
            _column(b, float(x), zc, pf, Hc, rad)
        b.add("portico", _box((-W / 2 - 1.3 * rad, pf + Hc, R * 0.5),
                              (W / 2 + 1.3 * rad, pf + 1.2 * Hc, zc + 1.3 * rad)), "trim")
        hs = W / 2 + 1.3 * rad + 0.2
        g = _extrude(_gable_profile(hs, hs * math.tan(math.radians(15))), R * 0.5, zc + 1.5 * rad)
        b.add("pediment", _xf(g, None, (0.0, pf + 1.2 * Hc, 0.0)), "trim")
    elif extra == "ring":
        n = _ri(r, 12, 20)
        for k in range(n):
            a = 2 * np.pi * k / n
            _column(b, ring_r * math.sin(a), ring_r * math.cos(a), y0, 0.8 * Hd, ring_rad)
        rr = ring_r + 1.4 * ring_rad
        b.add("ring_entablature", _frustum(rr, rr, y0 + 0.8 * Hd, y0 + 0.92 * Hd, 32), "trim")
    return {"radius": R, "drum_height": Hd, "roof": dome, "extra": extra}


def _build_terrace(r: Rng, b: _Builder) -> dict[str, Any]:
    W, D = _u(r, 12.0, 26.0), _u(r, 8.0, 18.0)
    Hp = _u(r, 2.0, 5.0)
    b.add("platform", _box((-W / 2, 0.0, -D / 2), (W / 2, Hp, D / 2)), "masonry")
    n = max(4, int(round(Hp / _u(r, 0.15, 0.22))))
    rise = Hp / n
    run = _u(r, 0.3, 0.45)
    sw = _u(r, 0.3, 0.7) * W
    stairs = _xf(_extrude_x(_stairs_profile(n, rise, run), -sw / 2, sw / 2), None, (0.0, 0.0, D / 2 - 0.02))
    b.add("stairs", stairs, "paving")
    # Side walls flanking the flight, and a balustrade-like parapet around the terrace.
    for s in (-1, 1):
        g = _extrude_x(np.array([(0.0, 0.0), (n * run, 0.0), (n * run, 0.9), (0.0, Hp + 0.9)]),
                       s * sw / 2 + (0.0 if s > 0 else -0.6), s * sw / 2 + (0.6 if s > 0 else 0.0))
        b.add("parapet", _xf(g, None, (0.0, 0.0, D / 2 - 0.02)), "trim")
    pt = 0.4
    for x0, x1 in ((-W / 2, -sw / 2 - 0.6), (sw / 2 + 0.6, W / 2)):
        if x1 - x0 > 0.5:
            b.add("parapet", _box((x0, Hp, D / 2 - pt), (x1, Hp + 0.9, D / 2)), "trim")
    b.add("parapet", _box((-W / 2, Hp, -D / 2), (-W / 2 + pt, Hp + 0.9, D / 2 - pt)), "trim")
    b.add("parapet", _box((W / 2 - pt, Hp, -D / 2), (W / 2, Hp + 0.9, D / 2 - pt)), "trim")
    crown = _pick(r, ("pavilion", "building", "statue"))
    if crown == "building":
        bw, bd = W * _u(r, 0.4, 0.7), D * _u(r, 0.3, 0.5)
        bh = _u(r, 3.5, 8.0)
        cz = -D / 2 + bd / 2 + 0.6
        b.add("walls", _box((-bw / 2, Hp, cz - bd / 2), (bw / 2, Hp + bh, cz + bd / 2)), "walls")
        rows = [Hp + 0.55 * bh]
        _windows_on_block(b, 0.0, cz, bw, bd, rows, 1.1, min(1.8, 0.5 * bh), 3.0, lambda x, z: False)
        _roof(b, _pick(r, ("gable", "hip", "flat")), 0.0, cz, bw, bd, Hp + bh, r)
    elif crown == "pavilion":
        pr = 0.22 * min(W, D)
        _pavilion(r, b, 0.0, -D / 2 + pr + 1.5, Hp, pr)  # floor circumradius pr + 0.8 stays on the terrace
    else:
        _statue_on_pedestal(b, r, 0.0, -D / 6, Hp, _u(r, 1.5, 2.5))
    return {"width": W, "depth": D, "platform_height": Hp, "steps": n, "crown": crown}


def _pavilion(r: Rng, b: _Builder, cx: float, cz: float, y0: float, R: float) -> dict[str, Any]:
    n = _pick(r, (4, 6, 8))
    Hc = _u(r, 3.0, 5.5)
    rad = _u(r, 0.18, 0.3)
    b.add("floor", _xf(_frustum(R + 0.8, R + 0.8, y0, y0 + 0.4, n, smooth=False, phase=np.pi / n), None, (cx, 0.0, cz)),
          "paving")
    for k in range(n):
        a = np.pi / n + 2 * np.pi * k / n
        _column(b, cx + R * math.sin(a), cz + R * math.cos(a), y0 + 0.4, Hc, rad, slot="trim")
    yt = y0 + 0.4 + Hc
    b.add("entablature", _xf(_frustum(R + 0.5, R + 0.5, yt, yt + 0.5, n, smooth=False, phase=np.pi / n), None,
                             (cx, 0.0, cz)), "trim")
    roof = _pick(r, ("pyramid", "dome", "tent"))
    if roof == "dome":
        g = _ellipsoid((R + 0.5, _u(r, 0.6, 1.0) * R, R + 0.5), (0.0, yt + 0.5, 0.0), 6, 24, hemi=True)
    else:
        h = (R + 0.6) * (_u(r, 0.6, 1.0) if roof == "pyramid" else _u(r, 1.2, 2.0))
        g = _frustum(R + 0.7, 0.0, yt + 0.5, yt + 0.5 + h, n, smooth=False, phase=np.pi / n)
    b.add("roof", _xf(g, None, (cx, 0.0, cz)), "roof")
    return {"columns": n, "roof": roof, "radius": R}


def _build_pavilion(r: Rng, b: _Builder) -> dict[str, Any]:
    R = _u(r, 2.5, 6.0)
    steps = _ri(r, 0, 3)
    y0 = _stepped_base(b, R + 1.2, R + 1.2, steps, 0.3, 0.4, part="steps") if steps else 0.0
    p = _pavilion(r, b, 0.0, 0.0, y0, R)
    p["steps"] = steps
    return p


_BUILDERS: dict[str, Callable[[Rng, _Builder], dict[str, Any]]] = {
    "building": _build_building,
    "tower": _build_tower,
    "temple": _build_temple,
    "colonnade": _build_colonnade,
    "arch": _build_arch,
    "wall": _build_wall,
    "monument": _build_monument,
    "rotunda": _build_rotunda,
    "terrace": _build_terrace,
    "pavilion": _build_pavilion,
}


# ---- props and trees ------------------------------------------------------------------


def _build_prop(r: Rng, b: _Builder) -> tuple[float, float]:
    """One prop around the local origin; returns (bounding radius, top height)."""
    kind = _pick(r, ("statue", "statue", "obelisk", "fountain", "low_wall"))
    if kind == "statue":
        top = _statue_on_pedestal(b, r, 0.0, 0.0, 0.0, _u(r, 0.8, 1.6), part="statue", ped_part="pedestal")
        return 1.2, top
    if kind == "obelisk":
        w = _u(r, 0.5, 0.9)
        h = _u(r, 4.0, 8.0)
        b.add("pedestal", _box((-1.5 * w, 0.0, -1.5 * w), (1.5 * w, 0.8, 1.5 * w)), "trim")
        ob = _frustum(w * math.sqrt(2), 0.6 * w * math.sqrt(2), 0.8, 0.8 + h, 4, smooth=False, phase=np.pi / 4)
        tip = _frustum(0.6 * w * math.sqrt(2), 0.0, 0.8 + h, 1.3 + h, 4, smooth=False, phase=np.pi / 4)
        b.add("obelisk", _cat([ob, tip]), "masonry")
        return 2.2 * w, 1.3 + h
    if kind == "fountain":
        R = _u(r, 1.5, 3.0)
        b.add("basin", _frustum(R, R, 0.0, 0.6, 24), "trim")
        b.add("basin", _frustum(0.3 * R, 0.25 * R, 0.6, 1.6, 16), "trim")
        b.add("basin", _frustum(0.5 * R, 0.5 * R, 1.6, 1.8, 16), "trim")
        return R, 1.8
    L = _u(r, 4.0, 9.0)
    h = _u(r, 0.8, 1.6)
    b.add("low_wall", _box((-L / 2, 0.0, -0.3), (L / 2, h, 0.3)), "masonry")
    b.add("coping", _box((-L / 2 - 0.05, h, -0.35), (L / 2 + 0.05, h + 0.12, 0.35)), "trim")
    return L / 2, h + 0.12


def _tree(r: Rng) -> tuple[list[_Geom], list[_Geom], float, float]:
    """Trunk and crown geometry of one tree at the origin: (trunks, crowns, radius, height)."""
    kind = _pick(r, ("conifer", "deciduous", "deciduous", "poplar", "cluster"))
    h = _u(r, 4.0, 14.0)
    tr = _u(r, 0.12, 0.22) * (h / 8.0) ** 0.5
    if kind == "conifer":
        cr = h * _u(r, 0.18, 0.3)
        trunk = [_frustum(tr, 0.7 * tr, 0.0, 0.3 * h, 8)]
        layers = _ri(r, 1, 3)
        crowns = []
        for k in range(layers):
            y0 = h * (0.2 + 0.22 * k)
            rk = cr * (1.0 - 0.22 * k)
            crowns.append(_frustum(rk, 0.0, y0, min(h, y0 + h * (0.8 - 0.2 * k)), 12))
        return trunk, crowns, cr, h
    if kind == "poplar":
        cr = h * _u(r, 0.1, 0.16)
        trunk = [_frustum(tr, 0.7 * tr, 0.0, 0.35 * h, 8)]
        return trunk, [_ellipsoid((cr, 0.42 * h, cr), (0.0, 0.56 * h, 0.0), 8, 12)], cr, h
    cr = h * _u(r, 0.28, 0.4)
    ht = h - 1.6 * cr
    trunk = [_frustum(tr, 0.7 * tr, 0.0, ht + 0.3 * cr, 8)]
    if kind == "deciduous":
        return trunk, [_ellipsoid((cr, 0.8 * cr, cr), (0.0, h - 0.8 * cr, 0.0), 8, 14)], cr, h
    crowns = [_ellipsoid((0.75 * cr,) * 3, (0.0, h - 0.75 * cr, 0.0), 6, 10)]
    for k in range(_ri(r, 2, 3)):
        a = 2 * np.pi * (k / 3.0 + _u(r, 0.0, 0.2))
        c = (0.45 * cr * math.sin(a), h - 1.1 * cr, 0.45 * cr * math.cos(a))
        crowns.append(_ellipsoid((0.6 * cr,) * 3, c, 6, 10))
    return trunk, crowns, cr, h
