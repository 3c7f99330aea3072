#!/usr/bin/env python3
"""Seed 001's scenario as bundled data: 12 beacons (data/beacons.csv; 5x
larger in data/seed001_beacons.csv, the EKF scenario's scale) and a
smooth planned tour through them in order (data/beacon_tour.csv, `t,x,y,theta`
at 10 Hz), for `kinegen inverse` and `kinegen simulate --trajectory beacons`.

The tour is a centripetal Catmull-Rom spline through the beacons, driven at a
constant 1 m/s with the heading along the tangent (a path a differential drive
can follow exactly). Run from the repository root: python3 scripts/beacon_tour.py
"""
import math

BEACONS = [(4, 0), (8, 2), (10, 6), (8, 10), (4, 11), (0, 10),
           (-3, 7), (-4, 3), (-2, -1), (2, -3), (6, -4), (10, -2)]
SPEED = 1.0  # m/s
RATE = 10.0  # Hz


def catmull_rom(p0, p1, p2, p3, n):
    def tj(ti, a, b):
        return ti + math.dist(a, b) ** 0.5
    t0 = 0.0
    t1 = tj(t0, p0, p1)
    t2 = tj(t1, p1, p2)
    t3 = tj(t2, p2, p3)
    out = []
    for i in range(n):
        t = t1 + (t2 - t1) * i / n
        def lerp(a, b, ta, tb):
            return tuple(((tb - t) * x + (t - ta) * y) / (tb - ta) for x, y in zip(a, b))
        a1, a2, a3 = lerp(p0, p1, t0, t1), lerp(p1, p2, t1, t2), lerp(p2, p3, t2, t3)
        b1, b2 = lerp(a1, a2, t0, t2), lerp(a2, a3, t1, t3)
        out.append(lerp(b1, b2, t1, t2))
    return out


def main():
    pts = [(0.0, 0.0)] + [tuple(map(float, b)) for b in BEACONS]
    # phantom end points, mirrored, so the first and last pieces have tangents
    first = (2 * pts[0][0] - pts[1][0], 2 * pts[0][1] - pts[1][1])
    last = (2 * pts[-1][0] - pts[-2][0], 2 * pts[-1][1] - pts[-2][1])
    ext = [first] + pts + [last]
    dense = []
    for i in range(len(pts) - 1):
        dense += catmull_rom(ext[i], ext[i + 1], ext[i + 2], ext[i + 3], 400)
    dense.append(pts[-1])
    # resample at constant speed
    s = [0.0]
    for a, b in zip(dense, dense[1:]):
        s.append(s[-1] + math.dist(a, b))
    step = SPEED / RATE
    rows, j, target = [], 0, 0.0
    while target <= s[-1]:
        while s[j + 1] < target:
            j += 1
        f = (target - s[j]) / max(s[j + 1] - s[j], 1e-12)
        x = dense[j][0] + f * (dense[j + 1][0] - dense[j][0])
        y = dense[j][1] + f * (dense[j + 1][1] - dense[j][1])
        rows.append((x, y))
        target += step
    with open('data/beacon_tour.csv', 'w') as f:
        f.write('t,x,y,theta\n')
        for k, (x, y) in enumerate(rows):
            a, b = rows[max(k - 1, 0)], rows[min(k + 1, len(rows) - 1)]
            th = math.atan2(b[1] - a[1], b[0] - a[0])
            f.write(f'{k / RATE:.2f},{x:.6f},{y:.6f},{th:.6f}\n')
    with open('data/beacons.csv', 'w') as f:
        f.write('id,x,y\n')
        for i, (x, y) in enumerate(BEACONS):
            f.write(f'B{i + 1},{x},{y}\n')
    # the seed's scale for the EKF scenario (a 5 m/s tour, beacons 20-50 m apart)
    with open('data/seed001_beacons.csv', 'w') as f:
        f.write('id,x,y\n')
        for i, (x, y) in enumerate(BEACONS):
            f.write(f'B{i + 1},{5 * x},{5 * y}\n')


if __name__ == '__main__':
    main()
