#!/usr/bin/python3
# Writes the terrain benchmark's procedural rough DEM: a SIZE x SIZE
# float32 GeoTIFF (UTM zone 10N, 10 m samples) of ridged fractal noise with
# a 300 m cliff across it and single-sample spikes: ground where no level
# of a height pyramid is a good model of the one below, to push terrain
# methods to where they fail. Deterministic (fixed seed).
#
#   /usr/bin/python3 scripts/make_rough_dem.py OUT.tif [SIZE]   (default 1024)
#
# Needs Debian's python3-gdal and python3-numpy (scripts/deps.sh --bench).
import sys

import numpy as np
from osgeo import gdal, osr


def main() -> int:
    if len(sys.argv) not in (2, 3):
        print("usage: make_rough_dem.py OUT.tif [SIZE]", file=sys.stderr)
        return 2
    out = sys.argv[1]
    size = int(sys.argv[2]) if len(sys.argv) == 3 else 1024
    if not 16 <= size <= 16384:
        print("SIZE must be 16..16384", file=sys.stderr)
        return 2
    rng = np.random.default_rng(20261203)
    heights = np.zeros((size, size), dtype=np.float64)
    amplitude, cells = 600.0, 4
    while cells <= size:
        # One octave: value noise on a cells x cells lattice, bilinear.
        lattice = rng.random((cells + 1, cells + 1))
        t = np.linspace(0.0, cells, size, endpoint=False)
        i = t.astype(int)
        f = t - i
        a = lattice[np.ix_(i, i)] * (1 - f)[None, :] + lattice[np.ix_(i, i + 1)] * f[None, :]
        b = lattice[np.ix_(i + 1, i)] * (1 - f)[None, :] + lattice[np.ix_(i + 1, i + 1)] * f[None, :]
        octave = a * (1 - f)[:, None] + b * f[:, None]
        heights += amplitude * (1.0 - np.abs(2.0 * octave - 1.0))  # ridged
        amplitude *= 0.55
        cells *= 2
    heights[:, size * 5 // 8:] += 300.0  # a cliff
    spikes = rng.random((size, size)) < 0.0005
    heights[spikes] += 250.0
    driver = gdal.GetDriverByName("GTiff")
    ds = driver.Create(out, size, size, 1, gdal.GDT_Float32, ["COMPRESS=DEFLATE", "TILED=YES"])
    ds.SetGeoTransform((500000.0, 10.0, 0.0, 5200000.0, 0.0, -10.0))
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32610)
    ds.SetProjection(srs.ExportToWkt())
    ds.GetRasterBand(1).WriteArray(heights.astype(np.float32))
    ds.FlushCache()
    ds = None
    return 0


if __name__ == "__main__":
    sys.exit(main())
