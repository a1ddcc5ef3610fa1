"""cellflip's volume measure (paper eq. volume; src/stages/volume.rs `cell_volume`, src/stages/markings.rs)
applied to MantaFlow's particles and level set, with numpy.

Imported by manta_dam.py (inside MantaFlow's embedded Python, which needs numpy importable) and
by volume.py; `python3 volume_measure.py` runs its self-checks (the cases of cellflip's own tests).

The measure, as cellflip computes it on its N^dim cells (walls outside them, no solids in the dam):
  fluid     a cell holding a particle (nbflip: or with phi < 0 at its centre)
  surface   a fluid cell with an empty cell among its 8 (2D) / 26 (3D) Moore neighbours inside
            the domain: cells beyond the domain's walls do not count (depth 0)
  depth -1  a fluid cell, not surface, with a surface cell among its 4 / 6 von Neumann neighbours
  V_c       min(1, n_c / mu) for surface and depth -1 cells, 1 for deeper fluid cells, 0 otherwise
  V         sum of V_c;  volume % = 100 V / V*,  V* = (initial particles) / mu
"""
import gzip
import itertools

import numpy as np

PDELETE = 1 << 10  # MantaFlow's ParticleBase::PDELETE


def read_particles_uni(path):
    """Positions (n x 3, grid units) of a MantaFlow BasicParticleSystem saved as .uni (PB02)."""
    b = gzip.open(path, "rb").read()
    if b[:4] != b"PB02":
        raise ValueError(f"{path}: not a PB02 particle file")
    n = int(np.frombuffer(b, dtype="<i4", count=1, offset=4)[0])
    # header: 6 ints, 256 chars of build info, an 8-byte timestamp (288 bytes after the id)
    rec = np.frombuffer(b, dtype=[("p", "<f4", 3), ("f", "<i4")], count=n, offset=4 + 288)
    return rec["p"][(rec["f"] & PDELETE) == 0].astype(np.float64)


def rejitter_particles_uni(src, dst, ppc1d, jitter, seed, dim):
    """Writes to `dst` the particles of `src` (MantaFlow's sub-cell samples, jittered by less than
    a quarter of their spacing) with the jitter redrawn: uniform in +-jitter cells per axis, from
    numpy's generator seeded with `seed` (2D: z stays 0.5). For an ensemble of MantaFlow runs."""
    b = gzip.open(src, "rb").read()
    n = int(np.frombuffer(b, dtype="<i4", count=1, offset=4)[0])
    rec = np.frombuffer(b, dtype=[("p", "<f4", 3), ("f", "<i4")], count=n, offset=4 + 288).copy()
    p = rec["p"].astype(np.float64)
    p = (np.floor(p * ppc1d) + 0.5) / ppc1d + np.random.default_rng(seed).uniform(-jitter, jitter, p.shape)
    if dim == 2:
        p[:, 2] = 0.5
    rec["p"] = p.astype(np.float32)
    with gzip.open(dst, "wb", compresslevel=1) as f:
        f.write(b[:4 + 288])
        f.write(rec.tobytes())


def read_grid_npz(path, dim, off, n):
    """A MantaFlow grid saved as .npz, as an array indexed [x, y(, z)] over the N^dim fluid cells."""
    a = np.load(path)["arr_0"]  # (z, y, x, 1)
    a = a[..., 0]
    if dim == 2:
        a = a[0]  # (y, x)
        return np.ascontiguousarray(a[off:off + n, off:off + n].T)
    return np.ascontiguousarray(a[off:off + n, off:off + n, off:off + n].transpose(2, 1, 0))


def cell_counts(pos, dim, off, n):
    """Particles per cell on the N^dim fluid cells, indexed [x, y(, z)]; particles outside them
    (in MantaFlow's wall layer) count in the nearest fluid cell. Returns (counts, outside)."""
    ijk = np.floor(pos[:, :dim]).astype(np.int64) - off
    outside = int(np.count_nonzero((ijk < 0) | (ijk >= n)))
    ijk = np.clip(ijk, 0, n - 1)
    flat = np.ravel_multi_index(tuple(ijk.T), (n,) * dim)
    return np.bincount(flat, minlength=n ** dim).reshape((n,) * dim), outside


def _any_neighbour(mask, offsets):
    """Cells with a neighbour at one of `offsets` where `mask` holds; beyond the edges: False."""
    dim = mask.ndim
    p = np.pad(mask, 1, constant_values=False)
    out = np.zeros_like(mask)
    n = mask.shape
    for o in offsets:
        sl = tuple(slice(1 + o[k], 1 + o[k] + n[k]) for k in range(dim))
        out |= p[sl]
    return out


def moore_offsets(dim):
    return [o for o in itertools.product((-1, 0, 1), repeat=dim) if any(o)]


def von_neumann_offsets(dim):
    out = []
    for k in range(dim):
        for s in (-1, 1):
            o = [0] * dim
            o[k] = s
            out.append(tuple(o))
    return out


def eq_volume(counts, mu, extra_fluid=None, solid=None):
    """V of eq. volume in cells. `counts`: particles per cell; `extra_fluid`: cells fluid without
    particles (nbflip's phi < 0); `solid`: solid cells (none in the dam). Returns (V, fluid cells)."""
    dim = counts.ndim
    fluid = counts > 0
    if extra_fluid is not None:
        fluid |= extra_fluid
    if solid is not None:
        fluid &= ~solid
        empty = ~fluid & ~solid
    else:
        empty = ~fluid
    surface = fluid & _any_neighbour(empty, moore_offsets(dim))
    near = fluid & ~surface & _any_neighbour(surface, von_neumann_offsets(dim))
    partial = surface | near
    deep = fluid & ~partial
    v = np.minimum(1.0, counts[partial] / float(mu)).sum() + np.count_nonzero(deep)
    return float(v), int(np.count_nonzero(fluid))


def _self_check():
    # src/stages/markings.rs block_of_fluid_has_surface_ring_and_depth_2d: a 5x4 block in an 8x8
    # tank, one particle per cell: surface only on the top and right sides
    c = np.zeros((8, 8), dtype=np.int64)
    c[:5, :4] = 1
    fluid = c > 0
    surf = fluid & _any_neighbour(~fluid, moore_offsets(2))
    assert surf[4, 0] and surf[0, 3] and not surf[0, 0] and not surf[3, 2]
    near = fluid & ~surf & _any_neighbour(surf, von_neumann_offsets(2))
    assert near[3, 2] and not near[2, 1]
    # mu = 4, one particle per cell: the surface and depth -1 cells count 1/4 each
    v, nf = eq_volume(c, 4)
    n_partial = int(np.count_nonzero(surf | near))
    assert nf == 20 and abs(v - (n_partial * 0.25 + (20 - n_partial))) < 1e-12, (v, n_partial)
    # a full block of mu particles per cell has its volume in cells, in 2D and 3D
    for dim, mu in ((2, 4), (3, 8)):
        c = np.zeros((10,) * dim, dtype=np.int64)
        c[(slice(0, 4),) * dim] = mu
        assert eq_volume(c, mu)[0] == 4 ** dim
    # cells fluid without particles near the surface add nothing, deep ones a whole cell
    c = np.zeros((10, 10), dtype=np.int64)
    extra = np.zeros((10, 10), dtype=bool)
    extra[:6, :6] = True
    assert eq_volume(c, 4, extra)[0] == 16  # 6x6 in a corner: surface x or y = 5, depth -1 at 4, deep 4x4
    print("volume_measure: self-checks pass")


if __name__ == "__main__":
    _self_check()
