# Sourced by scripts/sweep.sh, sweep_terrain.sh, sweep_detail.sh and
# sweep_paged.sh: what they share.
#
# Their one optional argument, as QUICK and CHARTS_ONLY:
#   --quick        fewer frames, for a smoke run (CSV, charts and docs still written)
#   --charts-only  redo data, charts and docs from the last runs' outputs
QUICK=0; CHARTS_ONLY=0
case "${1:-}" in
  "") ;;
  --quick) QUICK=1 ;;
  --charts-only) CHARTS_ONLY=1 ;;
  *) echo "usage: scripts/$(basename "$0") [--quick | --charts-only]" >&2; exit 2 ;;
esac

# put_block DOC NAME GENERATED: replaces the lines of DOC from the one holding
# <!-- NAME:begin --> to the one holding <!-- NAME:end --> with the file
# GENERATED (which holds both markers), through a temporary renamed into
# place; returns 1, DOC untouched, when DOC has no such block.
put_block() {
  local doc=$1 name=$2 generated=$3
  grep -q "<!-- $name:begin -->" "$doc" 2>/dev/null || return 1
  awk -v gen="$generated" -v b="<!-- $name:begin -->" -v e="<!-- $name:end -->" \
    'index($0, b){while((getline l < gen)>0)print l; skip=1; next} index($0, e){skip=0; next} !skip' \
    "$doc" >"$doc.tmp.$$"
  mv -f "$doc.tmp.$$" "$doc"
}
