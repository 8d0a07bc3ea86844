#!/usr/bin/python3
"""Reads tile windows of a COG through GDAL, for bench_store_http's comparison.

Usage: gdal_read_windows.py URL TELEPORT [TELEPORT ...]
  URL       a GDAL path, e.g. /vsicurl/http://127.0.0.1:8080/cog.tif
  TELEPORT  windows read together, ';'-separated, each LEVEL:X0:Y0:X1:Y1 in
            128-pixel tiles of that level (level 0 = full resolution, level
            l = overview l-1)

Opens the dataset once, then for each teleport reads every window with
ReadRaster (all bands) and prints "TELEPORT_INDEX SECONDS" on stdout. Windows
at levels the COG has no overview for are skipped and counted on stderr.
"""
import sys
import time

from osgeo import gdal

TILE = 128

def main():
    gdal.UseExceptions()
    url = sys.argv[1]
    ds = gdal.Open(url)
    bands = [ds.GetRasterBand(i + 1) for i in range(ds.RasterCount)]
    overviews = bands[0].GetOverviewCount()
    skipped = 0
    for index, teleport in enumerate(sys.argv[2:]):
        start = time.perf_counter()
        for window in filter(None, teleport.split(";")):
            level, x0, y0, x1, y1 = (int(v) for v in window.split(":"))
            if level > overviews:
                skipped += 1
                continue
            if level == 0:
                width, height = ds.RasterXSize, ds.RasterYSize
                levels = bands
            else:
                levels = [b.GetOverview(level - 1) for b in bands]
                width, height = levels[0].XSize, levels[0].YSize
            px0, py0 = x0 * TILE, y0 * TILE
            px1, py1 = min(x1 * TILE, width), min(y1 * TILE, height)
            if px1 <= px0 or py1 <= py0:
                continue
            for band in levels:
                band.ReadRaster(px0, py0, px1 - px0, py1 - py0)
        print(index, time.perf_counter() - start, flush=True)
    if skipped:
        print(f"{skipped} windows at levels without an overview skipped", file=sys.stderr)

if __name__ == "__main__":
    main()
