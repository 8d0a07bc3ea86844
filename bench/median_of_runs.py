#!/usr/bin/env python3
"""Median of repeated bench_store_http runs, as a Markdown table.

Usage: bench/median_of_runs.py [--tsv] RUN1.tsv RUN2.tsv ...

--tsv: a tab-separated table instead (what docs/data/ holds).

Rows are matched by (reader, protocol, rtt_ms, in_flight); the timing
columns (open_ms, sharp_median_s, sharp_max_s, tiles_per_s) become the
median over the runs, the others (requests, bytes, which repeat exactly)
are the first run's.
"""
import collections
import statistics
import sys


def median(values):
    try:
        return statistics.median(float(v.split()[0]) for v in values)
    except ValueError:  # "-"
        return None


def main(paths):
    tsv = bool(paths) and paths[0] == '--tsv'
    if tsv:
        paths = paths[1:]
    rows = collections.OrderedDict()
    header = None
    for path in paths:
        with open(path) as f:
            for line in f:
                if line.startswith('#'):
                    continue
                fields = line.rstrip('\n').split('\t')
                if fields[0] == 'reader':
                    header = fields
                    continue
                rows.setdefault(tuple(fields[:4]), []).append(fields)
    if header is None:
        sys.exit('no bench_store_http table in ' + ' '.join(paths))
    formats = {'open_ms': '%.0f', 'sharp_median_s': '%.3f', 'sharp_max_s': '%.3f',
               'tiles_per_s': '%.0f'}
    if tsv:
        print('\t'.join(header))
    else:
        print('| ' + ' | '.join(h.replace('_', ' ') for h in header) + ' |')
        print('|' + '---|' * len(header))
    for runs in rows.values():
        out = list(runs[0])
        for column, fmt in formats.items():
            i = header.index(column)
            m = median([r[i] for r in runs])
            if m is not None:
                out[i] = fmt % m
        print('\t'.join(out) if tsv else '| ' + ' | '.join(out) + ' |')


if __name__ == '__main__':
    main(sys.argv[1:])
