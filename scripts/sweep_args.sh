# Sourced by scripts/sweep.sh, sweep_terrain.sh and sweep_paged.sh: their one
# optional argument, as QUICK and CHARTS_ONLY.
#   --quick        fewer frames, for a smoke run (CSV, charts and docs still written)
#   --charts-only  redo data, charts and docs from the last runs' outputs
QUICK=0; CHARTS_ONLY=0
case "${1:-}" in
  "") ;;
  --quick) QUICK=1 ;;
  --charts-only) CHARTS_ONLY=1 ;;
  *) echo "usage: scripts/$(basename "$0") [--quick | --charts-only]" >&2; exit 2 ;;
esac
