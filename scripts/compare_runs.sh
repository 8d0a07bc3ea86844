#!/usr/bin/env bash
# Behaviour unchanged: compares what the demo (scripts/demo.sh) and the quick
# sweep (SWEEP_ASAN=0 scripts/sweep.sh --quick) left in a checkout of an
# earlier commit, BEFORE, with what the programs of BUILD_DIR make now of the
# same inputs. Prints one line per item, "same" or "DIFFERENT: <the first
# difference>", then the counts; exits 1 on any difference.
#
# What it compares:
# - Stores: each store the demo and the sweep tiled (table STORES below) is
#   tiled again from the same input (BEFORE/data/...) with the same options,
#   or taken from TREE/out/... with --stores-from TREE, and compared with cmp
#   and, when the files differ, tile by tile: the header's fields, the
#   metadata block and, for every tile (level, x, y) of either store, its
#   stored payload (its size and checksum), or its value if it is constant, and
#   its height bounds in an elevation store, as `clipstream-info --json
#   --tiles` lists them from the index (the stored size and checksum stand
#   for the payload). Each new store must also pass clipstream-info --verify.
# - Deterministic flights: every sweep run whose BEFORE/out/sweep/NAME.cmd
#   has --deterministic, flown again by that command as written, in a scratch
#   folder laid out as BEFORE was (build/ is BUILD_DIR, out/sweep/ links to
#   the before tree's store and paths), so that the paths the outputs record
#   read the same. frames.csv, frames.json and summary.tsv are compared value
#   by value, less the fields below; the trace run's request trace
#   (out/sweep/orbit.trace) byte for byte, and its replays by clipstream-trace
#   (trace_N.txt) too. The sweep's runs save no PNG (--save-frames 0).
# - The demo's two flights (over the orthophoto, over the mountain) run in
#   real time (scripts/demo.sh gives no --deterministic): a tile lands when
#   a loader gets to it, so what hangs on that (hits, loads, bytes read,
#   uploads, queues, a frame drawn before its tiles landed) does not repeat.
#   They are flown again as the demo flies them (DEMO below, over the before
#   tree's stores), and compared on what does not hang on it: the settings,
#   the schedule (frame, t_s, cut) and what the frames show once their tiles
#   have landed (PSNR, errors, holes, terrain geometry), the frames.csv and
#   summary.tsv fields DEMO_FIELDS names (`compare.py picture`), and the
#   PNG frames saved, byte for byte. Those repeat in practice: every 150th
#   frame is drawn long after its tiles landed and each judged frame the
#   same (two new flights and the before tree's agreed on all of it, on a
#   loaded machine). frame_time.png is the demo's chart of frame times.
#
# What it leaves out, and why:
# - Fields that time this machine or measure its memory, which differ from
#   run to run: any whose name holds the word "ms" (frame_ms, streamer_ms,
#   upload_ms, draw_ms, readback_ms, frame_ms_mean/_p50/_p99/_max,
#   draw_ms_mean, upload_ms_per_tile, decode_ms_per_tile, render_cpu_ms_mean,
#   run_ms, preload_ms, queue_latency_p50_ms/_p99_ms, decode_ms_total) or
#   "rss" (peak_rss_mib, peak_rss_bytes), and pngs_written and pngs_dropped
#   (the PNG writer drops a frame when it falls behind). t_s and
#   time_to_sharp_* count path time and frames, not the clock: compared.
# - The sweep's real-time runs (rt1_*, rt2_*, buffering_*, ...: no
#   --deterministic): run twice, one differs from itself in its queue
#   depths, hit rates and loads, for the reason above. So do the stability
#   scenarios and the soak (their frame times and RSS).
# - Where a store's pages lie in its file: the encoder threads finish the
#   index pages in any order, so two tilings of one input differ in bytes
#   there (and in the page directories' offsets) though every tile agrees.
# - The flights of scripts/sweep_terrain.sh and sweep_paged.sh (under
#   out/sweep/terrain/, out/sweep/paged/): they record no .cmd; their stores
#   are compared. docs/data/*.csv: tables drawn from the summaries compared
#   here and from the real-time runs.
#
# An item that differs is made a second time with BUILD_DIR and the two new
# ones compared: one that differs from itself is reported "NOT REPEATABLE"
# (it belongs above, with its reason), not "DIFFERENT".
#
# Usage: scripts/compare_runs.sh BEFORE [BUILD_DIR] [--only REGEX] [--stores-from TREE] [--keep]
#   BEFORE      a checkout where the demo and the quick sweep ran (its out/, data/)
#   BUILD_DIR   the programs to check (default build)
#   --only REGEX  only the stores and flights whose name matches, e.g.
#               'sweep/(speed|turn)' (names as printed: demo/autzen.cstore,
#               sweep/speed_1, demo/fly)
#   --stores-from TREE  the new stores are TREE/out/... (where the demo and
#               the sweep ran with BUILD_DIR's programs), not tiled here
#   --keep      keep the scratch folder (/tmp/compare-*; kept anyway on a difference)
# All of it takes 5 to 7 minutes on 2 cores shared with builds: under one
# for the stores, 3 to 4 for the 58 flights, 1 to 2 for the demo's.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() { sed -n '/^# Usage:/,/^set /{/^set /d; s/^# \{0,1\}//; p}' "$0" >&2; exit 2; }
before="" build="" only="" stores_from="" keep=0
while (($#)); do
  case "$1" in
    --only) only=${2:?}; shift 2 ;;
    --stores-from) stores_from=$(realpath "${2:?}"); shift 2 ;;
    --keep) keep=1; shift ;;
    -h|--help|-*) usage ;;
    *) if [[ -z "$before" ]]; then before=$(realpath "$1"); elif [[ -z "$build" ]]; then build=$1
       else usage; fi; shift ;;
  esac
done
[[ -n "$before" && -d "$before/out" ]] || usage
build=$(realpath "${build:-build}")
PROGRAMS="tiler/clipstream-tile store/clipstream-info eval/clipstream-fly streamer/clipstream-trace"
for program in $PROGRAMS; do
  [[ -x "$build/$program" ]] || { echo "compare_runs: no $build/$program" >&2; exit 2; }
done

# The stores and how the scripts tile them: store|input|options (paths
# under BEFORE; the rough DEM is the one the sweep generated there).
STORES=(
  "demo/autzen.cstore|data/autzen.jpg|"
  "demo/helens.cstore|data/mount_st_helens_30m.tif|"
  "demo/helens_relief.cstore|data/mount_st_helens_30m.tif|--relief --relief-scale 8"
  "sweep/autzen.cstore|data/autzen.jpg|"
  "sweep/terrain/autzen.cstore|data/autzen.jpg|"
  "sweep/terrain/helens.cstore|data/mount_st_helens_30m.tif|"
  "sweep/terrain/rough.cstore|out/sweep/terrain/rough.tif|"
  "sweep/terrain/rainier.cstore|../shared/data/mt_rainier_90m.tif|"
)
# The demo's flights, as scripts/demo.sh flies them: name|store and arguments.
DEMO=(
  "fly|out/demo/autzen.cstore --path orbit --frames 600 --size 1280x720 --save-frames 150"
  "terrain|out/demo/helens_relief.cstore --elevation out/demo/helens.cstore --path data/helens_relief_orbit.json --speed 3 --frames 600 --rest-frames 30 --size 1280x720 --reference --reference-every 30 --save-frames 150"
)
# The fields of a real-time flight (frames.csv and summary.tsv) that repeat:
# its settings, its schedule and what its frames show (see above).
DEMO_FIELDS='frames?|t_s|cut|speed|upload_tiles|cache_mb|tile_format|ram_budget_mib|io_mode|texture_memory|'\
'terrain_method|gpu_texture_mib|height_texture_mib|.*psnr.*|.*abs_error|hole_pixels|frames_with_holes|'\
'frames_below_30db|identical_frames|time_to_sharp_.*|geo_error_.*|terrain_(triangles|rings|finest_level).*|'\
'ground_height|judged_triangles_mean'

scratch=$(mktemp -d /tmp/compare-XXXXXX)
start=$SECONDS
same=0 different=0 unrepeatable=0
finish() {
  if ((keep || different || unrepeatable)); then echo "compare_runs: outputs kept in $scratch"
  else rm -rf "$scratch"; fi
}
trap finish EXIT
# The programs are copied first (with the tiler's OpenImageIO module, which
# it finds beside itself), so that a build of BUILD_DIR meanwhile cannot
# change them between two runs.
for program in $PROGRAMS; do install -D "$build/$program" "$scratch/build/$program"; done
cp "$build"/tiler/*.so "$scratch/build/tiler/" 2>/dev/null || true
echo "compare_runs: $before against the programs of $build (built $(date -r "$build/eval/clipstream-fly" '+%F %T'))"
given_build=$build build=$scratch/build
export INFO=$build/store/clipstream-info  # compare.py store

# ---- the comparisons (python: tables, JSON and store indexes) ---------------
cat >"$scratch/compare.py" <<'PY'
"""compare.py MODE BEFORE AFTER: prints 'same' or 'DIFFERENT: ...' (exit 0 or 1).
MODE: values (frames.csv, summary.tsv or frames.json, less IGNORED fields),
picture (a real-time flight's frames.csv or summary.tsv: DEMO_FIELDS),
names (the frame_*.png in two folders), store (tile by tile, as
clipstream-info --tiles lists them; INFO names the program)."""
import csv, json, os, re, subprocess, sys

IGNORED = re.compile(r'(^|_)ms($|_)|rss|^pngs_(written|dropped)$')
PICTURE = re.compile(os.environ.get('DEMO_FIELDS', ''))

def table(path, keep):
    with open(path, newline='') as f:
        rows = list(csv.reader(f, delimiter='\t' if path.endswith('.tsv') else ','))
    columns = [i for i, name in enumerate(rows[0]) if keep(name)]
    return rows[0], [[row[i] for i in columns] for row in rows[1:]], [rows[0][i] for i in columns]

def table_difference(a, b, keep):
    header_a, rows_a, names = table(a, keep)
    header_b, rows_b, _ = table(b, keep)
    if header_a != header_b:
        return f'columns {header_a} vs {header_b}' if len(header_a) < 8 else \
            f'columns differ: {sorted(set(header_a) ^ set(header_b)) or "their order"}'
    for n, (row_a, row_b) in enumerate(zip(rows_a, rows_b), start=1):  # line 1: the header
        for name, x, y in zip(names, row_a, row_b):
            if x != y:
                return f'line {n + 1}, {name}: {x} vs {y}'
    if len(rows_a) != len(rows_b):
        return f'{len(rows_a) + 1} lines vs {len(rows_b) + 1}'

def without_ignored(value):
    if isinstance(value, dict):
        return {k: without_ignored(v) for k, v in value.items() if not IGNORED.search(k)}
    if isinstance(value, list):
        return [without_ignored(v) for v in value]
    return value

def json_difference(a, b, where=''):
    if type(a) != type(b):
        return f'{where or "top"}: {a!r:.40} vs {b!r:.40}'
    if isinstance(a, dict):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b:
                return f'{where}/{key} only {"after" if key in b else "before"}'
            found = json_difference(a[key], b[key], f'{where}/{key}')
            if found:
                return found
    elif isinstance(a, list):
        for i, (x, y) in enumerate(zip(a, b)):
            found = json_difference(x, y, f'{where}[{i}]')
            if found:
                return found
        if len(a) != len(b):
            return f'{where}: {len(a)} items vs {len(b)}'
    elif a != b:
        return f'{where}: {a} vs {b}'

def store(path):
    """What clipstream-info --json --tiles says of a store, less what names
    its file rather than its tiles: the header's fields, the metadata and,
    for every tile, its constant value or its stored size and checksum (and
    height bounds), from the index."""
    out = subprocess.run([os.environ['INFO'], '--json', '--tiles', path], check=True,
                         capture_output=True, text=True).stdout
    info = json.loads(out)
    for name in ('path', 'file_bytes', 'file', 'store'):
        info.pop(name, None)
    return info

def store_difference(a, b):
    """The first difference of two stores (None when none) and a's tile count."""
    info_a, info_b = store(a), store(b)
    found = json_difference(info_a, info_b)
    return found, len(info_a.get('tiles', []))

def png_names(folder):
    return sorted(name for name in os.listdir(folder) if re.fullmatch(r'frame_\d+\.png', name))

mode, a, b = sys.argv[1:4]
same = 'same'
try:
    if mode == 'store':
        found, tiles = store_difference(a, b)
        same = f'same (tile by tile, {tiles} tiles; the files differ where the index pages lie)'
    elif mode == 'names':
        found = png_names(a) != png_names(b) and f'{" ".join(png_names(a))} vs {" ".join(png_names(b))}'
    elif mode == 'picture':
        found = table_difference(a, b, PICTURE.fullmatch)
    elif a.endswith('.json'):
        with open(a) as file_a, open(b) as file_b:
            found = json_difference(without_ignored(json.load(file_a)), without_ignored(json.load(file_b)))
    else:
        found = table_difference(a, b, lambda name: not IGNORED.search(name))
except (OSError, ValueError, struct.error, csv.Error, IndexError) as error:
    found = f'cannot read them: {error}'
print(f'DIFFERENT: {found}' if found else same)
sys.exit(1 if found else 0)
PY
export DEMO_FIELDS

# compare MODE A B: the line for two files (folders for names), by cmp for
# bytes, else by compare.py.
compare() {
  local path
  for path in "$2" "$3"; do [[ -e "$path" ]] || { echo "DIFFERENT: no $path"; return 1; }; done
  if cmp -s "$2" "$3" 2>/dev/null; then
    if [[ $1 == store ]]; then echo "same (byte for byte)"; else echo same; fi
    return
  fi
  if [[ $1 != bytes ]]; then python3 "$scratch/compare.py" "$@"; return; fi
  echo "DIFFERENT: $(cmp "$2" "$3" 2>&1 | sed 's/.*differ: //')"; return 1
}
selected() { [[ -z "$only" || "$1" =~ $only ]]; }

# check NAME MAKE SPEC...: makes the item NAME into $scratch/first with
# `MAKE ROOT`, then compares each SPEC, MODE:FILE (FILE relative to
# BEFORE/out and to ROOT/out), by MODE. When a file differs the item is made
# once more, into $scratch/second, and each such file compared with the
# first: if any of them disagree as well, the item does not repeat itself
# and each of its differences is reported "NOT REPEATABLE", not "DIFFERENT".
check() {
  local name=$1 make=$2 log=$scratch/logs/${1//\//_} spec mode file result again i repeats=1
  local -a modes=() files=() results=() differing=()
  shift 2
  if ! "$make" "$scratch/first" >"$log.first" 2>&1; then
    printf '%-44s %s\n' "$name" "DIFFERENT: it fails now ($log.first: $(tail -n 1 "$log.first"))"
    different=$((different + 1)); return
  fi
  for spec in "$@"; do
    mode=${spec%%:*} file=${spec#*:}
    result=$(compare "$mode" "$before/out/$file" "$scratch/first/out/$file") || differing+=("${#files[@]}")
    modes+=("$mode") files+=("$file") results+=("$result")
  done
  if ((${#differing[@]})); then
    "$make" "$scratch/second" >"$log.second" 2>&1 || true
    for i in "${differing[@]}"; do
      again=$(compare "${modes[i]}" "$scratch/first/out/${files[i]}" "$scratch/second/out/${files[i]}") && continue
      repeats=0
      results[i]="NOT REPEATABLE: two runs now differ: ${again#DIFFERENT: }"
    done
    if ((!repeats)); then
      for i in "${differing[@]}"; do
        [[ ${results[i]} == NOT* ]] ||
          results[i]="NOT REPEATABLE: it differs from itself elsewhere; before/now: ${results[i]#DIFFERENT: }"
      done
    fi
  fi
  for i in "${!files[@]}"; do
    if [[ ${modes[i]} == names ]]; then files[i]+=" (PNG names)"; fi
    printf '%-44s %s\n' "${files[i]}" "${results[i]}"
    case "${results[i]}" in same*) same=$((same + 1)) ;; DIFFERENT*) different=$((different + 1)) ;;
      *) unrepeatable=$((unrepeatable + 1)) ;; esac
  done
}

# Two scratch trees laid out as BEFORE: the programs, the inputs, and the
# before tree's stores and flight paths (links; what the runs write is new).
for root in "$scratch/first" "$scratch/second"; do
  mkdir -p "$root/out/demo" "$root/out/sweep" "$scratch/logs"
  ln -s "$build" "$root/build"
  ln -s "$before/data" "$root/data"
  for file in "$before"/out/demo/*.cstore "$before"/out/sweep/{autzen.cstore,*.json}; do
    if [[ -e "$file" ]]; then ln -s "$file" "$root/out/${file#"$before/out/"}"; fi
  done
done

# The items' makers, MAKER ROOT: each reads its loop's variables and fails
# when a program does (check() calls them where errexit is off).

# ---- stores -------------------------------------------------------------------
# tile_store ROOT: tiles $input into ROOT/out/$store (or links --stores-from's).
tile_store() {
  local target=$1/out/$store
  rm -f "$target"; mkdir -p "$(dirname "$target")"
  if [[ -n "$stores_from" ]]; then ln -s "$stores_from/out/$store" "$target"; return; fi
  # shellcheck disable=SC2086  # options are words
  "$build/tiler/clipstream-tile" "$before/$input" "$target" --force --quiet --no-fsync $options || return
  "$build/store/clipstream-info" "$target" --verify
}
echo "== stores (BEFORE/out/... against $([[ -n "$stores_from" ]] && echo "$stores_from/out/..." || echo "a tiling by $given_build"))"
for entry in "${STORES[@]}"; do
  IFS='|' read -r store input options <<<"$entry"
  if [[ ! -f "$before/out/$store" ]] || ! selected "$store"; then continue; fi
  [[ -f "$before/$input" ]] || { printf '%-44s %s\n' "$store" "skipped: no $before/$input"; continue; }
  check "$store" tile_store "store:$store"
done
# A store the table does not know is named, not passed over in silence.
known=" ${STORES[*]%%|*} "
while read -r file; do
  [[ $known == *" ${file#"$before/out/"} "* ]] || echo "compare_runs: $file: its tiling is unknown, not compared" >&2
done < <(find "$before/out" -name '*.cstore')

# ---- deterministic flights of the sweep -----------------------------------------
# fly_sweep ROOT: the run's .cmd as written, from ROOT.
fly_sweep() {
  local replay budget
  local -a words
  read -ra words <"$before/out/sweep/$run.cmd"
  rm -rf "$1/out/sweep/$run"
  (cd "$1" && "${words[@]}") || return
  [[ $run == trace ]] || return 0
  # The trace's replays, as scripts/sweep.sh runs them.
  for replay in "$before"/out/sweep/trace_*.txt; do
    budget=${replay##*trace_}; budget=${budget%.txt}
    (cd "$1" && build/streamer/clipstream-trace out/sweep/orbit.trace --budget-mb "$budget" \
      >"out/sweep/trace_$budget.txt") || return
  done
}
echo "== deterministic flights (BEFORE/out/sweep/*.cmd with --deterministic)"
for cmd in "$before"/out/sweep/*.cmd; do
  run=$(basename "$cmd" .cmd)
  if ! grep -q -- '--deterministic' "$cmd" || ! selected "sweep/$run"; then continue; fi
  files=("values:sweep/$run/"{frames.csv,frames.json,summary.tsv})
  # (none in the quick sweep: it flies with --save-frames 0)
  for png in "$before/out/sweep/$run"/frame_[0-9]*.png; do
    if [[ -f "$png" ]]; then files+=("bytes:sweep/$run/${png##*/}"); fi
  done
  if [[ $run == trace ]]; then
    files+=(bytes:sweep/orbit.trace)
    for replay in "$before"/out/sweep/trace_*.txt; do files+=("bytes:sweep/$(basename "$replay")"); done
  fi
  check "sweep/$run" fly_sweep "${files[@]}"
done

# ---- the demo's real-time flights ------------------------------------------------
# fly_demo ROOT: the flight $flight (DEMO) over the before tree's stores.
fly_demo() {
  local -a words
  read -ra words <<<"$arguments"
  rm -rf "$1/out/demo/$flight"
  (cd "$1" && build/eval/clipstream-fly "${words[@]}" --out "out/demo/$flight")
}
echo "== the demo's flights (real time: settings, schedule and what the frames show)"
for entry in "${DEMO[@]}"; do
  IFS='|' read -r flight arguments <<<"$entry"
  if [[ ! -f "$before/out/demo/$flight/summary.tsv" ]] || ! selected "demo/$flight"; then continue; fi
  files=("picture:demo/$flight/"{frames.csv,summary.tsv} "names:demo/$flight")
  for png in "$before/out/demo/$flight"/frame_[0-9]*.png; do
    if [[ -f "$png" ]]; then files+=("bytes:demo/$flight/${png##*/}"); fi
  done
  check "demo/$flight" fly_demo "${files[@]}"
done

echo "compare_runs: $((same + different + unrepeatable)) items: $same same, $different different, $unrepeatable not repeatable ($((SECONDS - start)) s)"
((different == 0 && unrepeatable == 0))
