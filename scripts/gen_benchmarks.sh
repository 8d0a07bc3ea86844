#!/usr/bin/env bash
# Renders docs/benchmarks.md from its template, docs/benchmarks.md.in, and the
# tables the benchmark programs and scripts write under docs/data/. The
# template holds the prose (how to run, how to read); every table comes from
# a data file. Running it twice changes nothing; a missing file, column or
# row stops it with the template's line.
#
#   scripts/gen_benchmarks.sh            # rewrite docs/benchmarks.md
#   scripts/gen_benchmarks.sh --check    # exit 1, with a diff, when docs/benchmarks.md is not what it renders
#   scripts/gen_benchmarks.sh --data DIR [--data DIR...] [--out FILE]
#     --data  where the data files are (default docs/data); repeated, the
#             first folder holding a file wins (the sweeps name their own
#             output folder first, then docs/data)
#     --out   the document to write or check (default docs/benchmarks.md)
#
# Directives of the template:
#   {{table FILE[,FILE...] [columns=SPEC,...] [label=NAME:V1,V2,...] [pivot=ROW,COL] [where=COL=VALUE]}}
#       a line of its own: a Markdown table of FILE (.csv: comma-separated,
#       anything else tab-separated; lines opening with # and blank lines are
#       skipped, the first other line is the header, a later copy of the header
#       is skipped, so runs appended to one file stay one table).
#       columns: which columns, in order (default all); a column is NAME or
#         NAME:FORMAT (a printf format for numbers, e.g. %.1f), or several
#         joined with / (shown "a / b", each with its own format).
#       several FILEs (the runs of one command): their rows one after the
#         other; label=run:1,2 puts a first column "run" naming each file's rows.
#       pivot=ROW,COL: one row per value of ROW, one column per value of COL
#         (in order of appearance), each cell the columns' values there.
#       where=COL=VALUE: only the rows whose COL is VALUE.
#   {{value FILE KEY}}   anywhere: the second column of FILE's row whose first column is KEY
#   {{list FILE KEY}}    a line of its own: "- `VALUE`" for each such row
set -euo pipefail
cd "$(dirname "$0")/.."

template=docs/benchmarks.md.in
out=docs/benchmarks.md
check=0
dirs=()
while (($#)); do
  case $1 in
    --check) check=1 ;;
    --data) dirs+=("${2:?--data needs a folder}"); shift ;;
    --out) out=${2:?--out needs a file}; shift ;;
    *) echo "usage: scripts/gen_benchmarks.sh [--check] [--data DIR]... [--out FILE]" >&2; exit 2 ;;
  esac
  shift
done
((${#dirs[@]})) || dirs=(docs/data)
[[ -f $template ]] || { echo "gen_benchmarks: no $template" >&2; exit 1; }

render() {
  awk -v dirs="$(printf '%s\n' "${dirs[@]}")" -v template="$template" '
    function fail(msg) { printf "gen_benchmarks: %s:%d: %s\n", template, NR, msg > "/dev/stderr"; failed = 1; exit 1 }

    # The path of data file NAME: the first folder holding it.
    function locate(name,    i, p, line) {
      for (i = 1; i <= ndirs; i++) {
        p = dir[i] "/" name
        if ((getline line < p) >= 0) { close(p); return p }
      }
      fail("no data file " name " in " dirlist)
    }

    # Reads FILE into rows: nrows, cell[r, c], and the header: ncols, head[c], col[name].
    function load(name, label_value,    p, fs, line, n, f, i, header_line, r) {
      p = locate(name)
      fs = (name ~ /\.csv$/) ? "," : "\t"
      header_line = ""
      while ((getline line < p) > 0) {
        sub(/\r$/, "", line)
        if (line ~ /^#/ || line ~ /^[ \t]*$/) continue
        if (header_line == "") {
          header_line = line
          n = split(line, f, fs)
          if (loaded_header == "") {
            loaded_header = line; ncols = n
            for (i = 1; i <= n; i++) { head[i] = f[i]; col[f[i]] = i }
          } else if (line != loaded_header) {
            fail(name " has other columns than the first file of the table")
          }
          continue
        }
        if (line == header_line) continue
        n = split(line, f, fs)
        if (n != ncols) fail(name ": a row of " n " fields under a header of " ncols ": " line)
        r = ++nrows
        for (i = 1; i <= ncols; i++) cell[r, i] = (i <= n) ? f[i] : ""
        rowlabel[r] = label_value
      }
      close(p)
      if (header_line == "") fail(name " has no header row")
    }

    # One column spec (NAME[:FORMAT][/NAME[:FORMAT]...]) -> the parts: npart, pidx[], pfmt[], and its title.
    function parse_spec(spec,    parts, k, nm, colon) {
      npart = split(spec, parts, "/")
      spec_title = ""
      for (k = 1; k <= npart; k++) {
        nm = parts[k]; pfmt[k] = ""
        colon = index(nm, ":")
        if (colon) { pfmt[k] = substr(nm, colon + 1); nm = substr(nm, 1, colon - 1) }
        if (!(nm in col)) fail("no column " nm " in " files_text)
        pidx[k] = col[nm]
        spec_title = spec_title (k > 1 ? " / " : "") nm
      }
    }
    function value_of(r, k,    v) {
      v = cell[r, pidx[k]]
      if (pfmt[k] != "" && v ~ /^-?[0-9]+(\.[0-9]+)?([eE][-+]?[0-9]+)?$/) v = sprintf(pfmt[k], v)
      return v
    }
    # Joined parts skip empty values ("a / b" with b empty is "a").
    function spec_value(r,    k, s, v) {
      s = ""
      for (k = 1; k <= npart; k++) {
        v = value_of(r, k)
        if (v != "") s = s (s != "" ? " / " : "") v
      }
      return s
    }
    function md(v) { gsub(/\|/, "\\|", v); return v }

    function table(args,    words, nw, w, i, key, val, files, nfiles, labels, nlabels, label_name,
                   specs, nspecs, pivot, where_col, where_val, r, j, out_rows, line, numeric, nout,
                   grid, rkeys, nrk, ckeys, nck, seen_r, seen_c, rk, ck, ri, ci, pr, pc) {
      nw = split(args, words, /[ \t]+/)
      delete cell; delete head; delete col; delete rowlabel
      nrows = 0; ncols = 0; loaded_header = ""
      nfiles = split(words[1], files, ",")
      files_text = words[1]
      label_name = ""; nlabels = 0; nspecs = 0; pivot = ""; where_col = ""
      for (i = 2; i <= nw; i++) {
        w = words[i]
        if (w == "") continue
        key = substr(w, 1, index(w, "=") - 1); val = substr(w, index(w, "=") + 1)
        if (key == "columns") nspecs = split(val, specs, ",")
        else if (key == "label") {
          label_name = substr(val, 1, index(val, ":") - 1)
          nlabels = split(substr(val, index(val, ":") + 1), labels, ",")
          if (label_name == "" || nlabels != nfiles) fail("label= needs NAME: and one value per file")
        } else if (key == "pivot") pivot = val
        else if (key == "where") { where_col = substr(val, 1, index(val, "=") - 1); where_val = substr(val, index(val, "=") + 1) }
        else fail("unknown table option " w)
      }
      for (i = 1; i <= nfiles; i++) load(files[i], nlabels ? labels[i] : "")
      # The label is a column too (for pivot= and where=), shown first.
      if (label_name != "") {
        ncols++; head[ncols] = label_name; col[label_name] = ncols
        for (r = 1; r <= nrows; r++) cell[r, ncols] = rowlabel[r]
      }
      if (!nspecs) for (i = 1; i <= ncols; i++) specs[++nspecs] = head[i]
      if (where_col != "" && !(where_col in col)) fail("no column " where_col " in " files_text)

      # The output grid: out_head[j], out[i, j], nout rows, nocol columns.
      delete out; delete out_head; nout = 0; nocol = 0
      if (pivot != "") {
        split(pivot, pc, ",")
        if (!(pc[1] in col) || !(pc[2] in col)) fail("pivot= names a column " files_text " lacks")
        if (nspecs != 1) fail("pivot= takes one columns= spec")
        parse_spec(specs[1])
        nrk = 0; nck = 0
        for (r = 1; r <= nrows; r++) {
          if (where_col != "" && cell[r, col[where_col]] != where_val) continue
          rk = cell[r, col[pc[1]]]; ck = cell[r, col[pc[2]]]
          if (!(rk in seen_r)) { seen_r[rk] = ++nrk; rkeys[nrk] = rk }
          if (!(ck in seen_c)) { seen_c[ck] = ++nck; ckeys[nck] = ck }
          grid[seen_r[rk], seen_c[ck]] = spec_value(r)
        }
        out_head[++nocol] = pc[1]
        for (ci = 1; ci <= nck; ci++) out_head[++nocol] = pc[2] " " ckeys[ci]
        for (ri = 1; ri <= nrk; ri++) {
          nout++; out[nout, 1] = rkeys[ri]
          for (ci = 1; ci <= nck; ci++) out[nout, ci + 1] = ((ri, ci) in grid) ? grid[ri, ci] : ""
        }
      } else {
        if (label_name != "") out_head[++nocol] = label_name
        for (j = 1; j <= nspecs; j++) { parse_spec(specs[j]); out_head[++nocol] = spec_title }
        for (r = 1; r <= nrows; r++) {
          if (where_col != "" && cell[r, col[where_col]] != where_val) continue
          nout++; j = 0
          if (label_name != "") out[nout, ++j] = rowlabel[r]
          for (i = 1; i <= nspecs; i++) { parse_spec(specs[i]); out[nout, ++j] = spec_value(r) }
        }
      }
      if (nout == 0) fail("no rows in " files_text (where_col != "" ? " where " where_col "=" where_val : ""))

      line = "|"
      for (j = 1; j <= nocol; j++) line = line " " md(out_head[j]) " |"
      print line
      line = "|"
      for (j = 1; j <= nocol; j++) {
        numeric = 0
        for (i = 1; i <= nout; i++) {
          if (out[i, j] == "" || out[i, j] == "-" || out[i, j] == "nan") continue  # no value
          if (out[i, j] ~ /^-?[0-9]+(\.[0-9]+)?( \/ -?[0-9]+(\.[0-9]+)?)*$/) numeric = 1
          else { numeric = 0; break }
        }
        line = line (numeric ? "--:|" : "---|")
      }
      print line
      for (i = 1; i <= nout; i++) {
        line = "|"
        for (j = 1; j <= nocol; j++) line = line " " md(out[i, j]) " |"
        print line
      }
    }

    # Rows of a two-column key file whose first column is KEY -> keyed[1..n].
    function lookup(name, key,    p, fs, line, f, n, header_seen) {
      p = locate(name)
      fs = (name ~ /\.csv$/) ? "," : "\t"
      n = 0; header_seen = 0
      while ((getline line < p) > 0) {
        if (line ~ /^#/ || line ~ /^[ \t]*$/) continue
        if (!header_seen) { header_seen = 1; continue }
        split(line, f, fs)
        if (f[1] == key) keyed[++n] = substr(line, length(f[1]) + 2)
      }
      close(p)
      if (n == 0) fail("no row " key " in " name)
      return n
    }

    BEGIN { ndirs = split(dirs, dir, "\n"); while (ndirs && dir[ndirs] == "") ndirs--
            dirlist = ""; for (i = 1; i <= ndirs; i++) dirlist = dirlist (i > 1 ? ", " : "") dir[i] }
    NR == 1 { print "<!-- Generated by scripts/gen_benchmarks.sh from docs/benchmarks.md.in and docs/data/: edit those, then run it. -->" }
    /^\{\{table [^}]*\}\}[ \t]*$/ { s = $0; sub(/^\{\{table /, "", s); sub(/\}\}[ \t]*$/, "", s); table(s); next }
    /^\{\{list [^}]*\}\}[ \t]*$/ {
      s = $0; sub(/^\{\{list /, "", s); sub(/\}\}[ \t]*$/, "", s)
      if (split(s, a, " ") != 2) fail("{{list FILE KEY}} takes two words")
      n = lookup(a[1], a[2])
      for (i = 1; i <= n; i++) print "- `" keyed[i] "`"
      next
    }
    {
      line = $0
      while (match(line, /\{\{value [^}]*\}\}/)) {
        s = substr(line, RSTART + 8, RLENGTH - 10)
        if (split(s, a, " ") != 2) fail("{{value FILE KEY}} takes two words")
        n = lookup(a[1], a[2])
        line = substr(line, 1, RSTART - 1) keyed[1] substr(line, RSTART + RLENGTH)
      }
      if (line ~ /\{\{/) fail("a {{directive}} this script does not know: " line)
      print line
    }
    END { if (failed) exit 1 }
  ' "$template"
}

dir_of_out=$(dirname "$out")
tmp=$(mktemp "$dir_of_out/.benchmarks.md.XXXXXX")
trap 'rm -f "$tmp"' EXIT
render >"$tmp"
if ((check)); then
  if ! diff -u "$out" "$tmp" >&2; then
    echo "gen_benchmarks: $out is not what scripts/gen_benchmarks.sh renders from $template and ${dirs[*]}; run it" >&2
    exit 1
  fi
  echo "gen_benchmarks: $out is current"
  exit 0
fi
chmod 644 "$tmp"
mv -f "$tmp" "$out"
trap - EXIT
echo "gen_benchmarks: wrote $out"
