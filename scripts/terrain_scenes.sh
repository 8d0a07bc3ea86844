# Sourced by scripts/sweep_terrain.sh and sweep_detail.sh: the terrain scenes
# both fly (the scenes are described at the top of sweep_terrain.sh).
#
# Defines SCENES (rainier only where ../shared holds its DEM), and
# make_terrain_scenes, which needs BUILD and WORK: it tiles the stores into
# $WORK (each once) and fills SCENE (a scene's clipstream-fly arguments) and
# SPEED (its path speed); and value DIR KEY, the field KEY of a flight's
# DIR/summary.tsv.
SCENES="helens rough"
[ -f ../shared/data/mt_rainier_90m.tif ] && SCENES="helens rainier rough"
declare -A SCENE SPEED

make_terrain_scenes() {
  tile() { [ -f "$2" ] || "$BUILD/tiler/clipstream-tile" "$1" "$2" --quiet --no-fsync; }
  tile data/autzen.jpg "$WORK/autzen.cstore"
  tile data/mount_st_helens_30m.tif "$WORK/helens.cstore"
  [ -f "$WORK/rough.tif" ] || /usr/bin/python3 scripts/make_rough_dem.py "$WORK/rough.tif" 1024
  tile "$WORK/rough.tif" "$WORK/rough.cstore"
  local rainier=../shared/data/mt_rainier_90m.tif
  [ -f "$rainier" ] && tile "$rainier" "$WORK/rainier.cstore"
  cat >"$WORK/mountainside.json" <<'EOF'
{"keyframes": [
 {"t": 0,  "x": 15750, "y": 600, "z": 42000, "heading_deg": 0,   "pitch_deg": -8},
 {"t": 10, "x": 15750, "y": 600, "z": 24000, "heading_deg": 0,   "pitch_deg": -6},
 {"t": 16, "x": 9000,  "y": 600, "z": 17000, "heading_deg": 60,  "pitch_deg": -8},
 {"t": 24, "x": 22000, "y": 600, "z": 16000, "heading_deg": 0,   "pitch_deg": -6},
 {"t": 30, "x": 26000, "y": 900, "z": 9000,  "heading_deg": -90, "pitch_deg": -10}
]}
EOF
  SCENE[helens]="$WORK/autzen.cstore --elevation $WORK/helens.cstore --stretch-elevation --path data/helens_orbit.json"
  SPEED[helens]=12
  SCENE[rough]="--procedural 16384 --elevation $WORK/rough.cstore --stretch-elevation --path orbit"
  SPEED[rough]=1
  SCENE[rainier]="--procedural 65536 --elevation $WORK/rainier.cstore --stretch-elevation --path $WORK/mountainside.json"
  SPEED[rainier]=10
}

value() { awk -F'\t' -v k="$2" 'NR==1{for(i=1;i<=NF;i++) c[$i]=i} NR==2{print $(c[k])}' "$1/summary.tsv"; }
