#!/usr/bin/env bash
# Keeps the commands of README.md and docs/*.md runnable: fails, listing each
# problem as FILE:LINE: what is wrong, when
# - a command runs one of the programs (each clipstream_install_program() of
#   the CMakeLists) with a long option (--foo) that the program's --help,
#   from BUILD_DIR, does not list. A command is a line of a ```sh, ```bash,
#   ```shell or plain ``` block (of a ```console block only the `$ ` lines),
#   with the lines that end in \ and, in a synopsis, the indented lines that
#   open with [ joined to it; or an inline `code` span. It runs a program
#   when the program (by name or by a path to it) is the first word of the
#   command or of a part of it after ; && || | $( ( or an opening quote,
#   past any VAR=value words, time, parallel, bash and the like. An indented
#   line of a block that opens with --foo (an option table under synopses)
#   must name an option of a program the block ran before it. The other
#   programs (benchmarks, tests) have no --help to check against;
# - a command runs a program from a build folder, build*/DIR/NAME (any
#   program, the benchmarks' and tests' too), and DIR/ does not build NAME
#   (no CMake call there takes NAME first, as add_executable(NAME ...) does);
# - a command runs scripts/NAME.sh (or .py) with a --flag that neither the
#   script nor a script it sources contains;
# - a repository path named anywhere in the text does not exist.
#
# A repository path is a word that begins, relative to the repository's
# root, at one of its folders: scripts/ data/ docs/ bench/ tests/ examples/
# cmake/ store/ tiler/ streamer/ renderer/ eval/ cli/ .ci/ (./ allowed
# before it), with a trailing :LINE or #anchor left out. So what the commands
# write (out/..., build*/..., /tmp/..., any absolute path) and what users of
# a clone lack (../shared/...) are never repository paths, nor is a word
# with anything before the folder (build/tiler/..., $PWD/tests/...). Globs,
# variables and placeholders (a word with * ? { } < > $ or ...) are left
# out too. Two spellings pass without existing as written: a public header
# by its include path (streamer/tile_source.h for
# streamer/include/clipstream/streamer/tile_source.h) and a program by the
# folder that builds it (bench/tiler_decode, as for build*/DIR/NAME above).
#
# Called by scripts/test.sh right after the programs are built.
# Usage: scripts/check_docs.sh [BUILD_DIR [FILE.md...]]
#   BUILD_DIR  where the programs were built (default build); FILEs (default
#   README.md docs/*.md), like BUILD_DIR, absolute or relative to the
#   repository's root
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
shift || true
if (($#)); then docs=("$@"); else docs=(README.md docs/*.md); fi

problems=0
problem() { echo "$1: $2" >&2; problems=$((problems + 1)); }

# Each program's long options, from its --help: " --a --b ... ".
declare -A options
programs=()
while IFS=: read -r cmakelists program; do
  binary=$build/$(dirname "$cmakelists")/$program
  if [[ ! -x "$binary" ]]; then
    problem "$binary" "not built, so its options cannot be checked (cmake --build $build --target installables)"
    continue
  fi
  if ! help=$("$binary" --help 2>&1); then
    problem "$binary" "--help failed: $(tail -n 1 <<<"$help")"
    continue
  fi
  options[$program]=" $(grep -oE '^ +(-[A-Za-z0-9],)?--[A-Za-z0-9-]+' <<<"$help" | sed 's/.*--/--/' | tr '\n' ' ')"
  programs+=("$program")
done < <(grep -oE '^clipstream_install_program\([A-Za-z0-9_-]+' -- */CMakeLists.txt |
  sed 's/clipstream_install_program(//')
((problems == 0)) || { echo "check_docs: $problems program(s) in $build not built or not answering --help" >&2; exit 1; }
((${#programs[@]})) || { echo "check_docs: no clipstream_install_program() in */CMakeLists.txt" >&2; exit 1; }

# What the text names, a row each, tab-separated:
#   option FILE:LINE PROGRAM --opt     a program run with --opt
#   row    FILE:LINE "PROGRAM..." --opt  an option table's row under those programs
#   flag   FILE:LINE scripts/x.sh --flag
#   path   FILE:LINE PATH
#   built  FILE:LINE build.../DIR/NAME   a program run from a build folder
extract() {
  awk -v programs="${programs[*]}" '
    BEGIN {
      split(programs, p, " "); for (i in p) is_program[p[i]] = 1
      split("time sudo exec env nice nohup parallel xargs do then else ! $ bash sh python3", w, " ")
      for (i in w) wrapper[w[i]] = 1
      folders = "scripts|data|docs|bench|tests|examples|cmake|store|tiler|streamer|renderer|eval|cli|\\.ci"
      path_re = "(^|[^A-Za-z0-9_.$~/-])(\\./)?(" folders ")/[A-Za-z0-9_.*?{}<>$+=:#@%~/-]*"
    }
    function where(line) { return FILENAME ":" line }
    function emit(kind, line, what, arg) { print kind "\t" where(line) "\t" what "\t" arg }

    # Repository paths anywhere in the text.
    function paths(text, line,    rest, p) {
      rest = text
      while (match(rest, path_re)) {
        p = substr(rest, RSTART, RLENGTH); rest = substr(rest, RSTART + RLENGTH)
        sub(/^[^A-Za-z.]/, "", p); sub(/^\.\//, "", p)
        sub(/#.*/, "", p); sub(/[.,:;]+$/, "", p); sub(/:[0-9]+(-[0-9]+)?$/, "", p)
        if (p !~ /[*?{}<>$]|\.\.\./) emit("path", line, p, "")
      }
    }

    # A command: which programs and scripts it runs, with which long options.
    function command(text, line,    parts, n, s, words, nw, i, word, base, run, o) {
      sub(/(^|[ \t])#.*/, "", text)
      gsub(/&&|\|\||;|\$\(|[()]|[ \t]\|[ \t]|(^|[ \t])\x27/, "\n", text)
      n = split(text, parts, "\n")
      for (s = 1; s <= n; s++) {
        nw = split(parts[s], words, /[ \t]+/); run = ""
        for (i = 1; i <= nw; i++) {
          word = words[i]; gsub(/["\x27]/, "", word)
          if (word == "") continue
          if (run == "") {
            if (word ~ /^[A-Za-z_][A-Za-z0-9_]*=/ || word in wrapper) continue
            if (word ~ /^(\.\/)?build[^\/]*\/.+\/[^\/.]+$/) emit("built", line, word, "")
            base = word; sub(/.*\//, "", base)
            if (base in is_program) { run = base; kind = "option"; ran[base] = 1; continue }
            if (word ~ /^(\.\/)?scripts\/[A-Za-z0-9_.-]+\.(sh|py)$/) {
              run = word; sub(/^\.\//, "", run); kind = "flag"; continue
            }
            break
          }
          if (match(word, /^\[*--[A-Za-z0-9][A-Za-z0-9_-]*/)) {
            o = substr(word, RSTART, RLENGTH); sub(/^\[*/, "", o)
            emit(kind, line, run, o)
          }
        }
      }
    }
    function flush() { if (pending != "") command(pending, pending_line); pending = "" }

    FNR == 1 { fence = ""; pending = ""; span = ""; in_span = 0 }
    { paths($0, FNR) }

    /^[ \t]*```/ {
      if (fence == "") {
        lang = $0; sub(/^[ \t]*```[ \t]*/, "", lang)
        fence = lang ~ /^(sh|bash|shell|console)?$/ ? "commands" : "other"
        console = lang == "console"
        split("", ran)
      } else { flush(); fence = "" }
      in_span = 0; span = ""
      next
    }
    fence == "other" { next }
    fence == "commands" {
      text = $0
      if (pending ~ /\\[ \t]*$/ || (pending != "" && text ~ /^[ \t]+\[/)) {
        sub(/\\[ \t]*$/, "", pending); pending = pending " " text; next
      }
      flush()
      if (console && text !~ /^[ \t]*\$ /) next
      if (match(text, /^[ \t]+--[A-Za-z0-9][A-Za-z0-9_-]*/)) {
        o = substr(text, RSTART, RLENGTH); sub(/^[ \t]+/, "", o); programs_ran = ""
        for (r in ran) programs_ran = programs_ran " " r
        if (programs_ran != "") emit("row", FNR, substr(programs_ran, 2), o)
        next
      }
      pending = text; pending_line = FNR
      next
    }

    # Inline code spans, which may run over several lines of a paragraph.
    /^[ \t]*$/ { in_span = 0; span = ""; next }
    {
      n = split($0, pieces, "`")
      for (i = 1; i <= n; i++) {
        if (i > 1) {
          in_span = !in_span
          if (in_span) { span = ""; span_line = FNR }
          else command(span, span_line)
        }
        if (in_span) span = span (i == 1 ? " " : "") pieces[i]
      }
    }
    END { flush() }
  ' "${docs[@]}"
}

# builds DIR NAME: a CMake call in DIR/CMakeLists.txt or DIR/*.cmake takes NAME first.
builds() { grep -qsE "^[[:space:]]*[A-Za-z_]+\($2[[:space:])]" "$1"/CMakeLists.txt "$1"/*.cmake; }

rows=$(extract)  # here, so that a failing awk fails the check
declare -A handles  # "script --flag" -> 0 or 1
while IFS=$'\t' read -r kind where what arg; do
  case $kind in
    built)
      relative=${what#./} relative=${relative#*/}
      builds "${relative%/*}" "${relative##*/}" || problem "$where" "$what: ${relative%/*}/ builds no ${relative##*/}"
      ;;
    option)
      [[ ${options[$what]} == *" $arg "* ]] || problem "$where" "$what has no option $arg (its --help does not list it)"
      ;;
    row)
      for program in $what; do [[ ${options[$program]} == *" $arg "* ]] && continue 2; done
      problem "$where" "$arg is an option of none of the block's programs ($what)"
      ;;
    flag)
      [[ -f "$what" ]] || continue  # reported as a path
      if [[ -z "${handles["$what $arg"]:-}" ]]; then
        # The script and the scripts/ files it sources.
        mapfile -t files < <(echo "$what"; sed -nE 's/^(source|\.) +(scripts\/[A-Za-z0-9_.-]+).*/\2/p' "$what")
        handles["$what $arg"]=$(grep -qE -- "(^|[^A-Za-z0-9_-])$arg([^A-Za-z0-9_-]|\$)" "${files[@]}" && echo 1 || echo 0)
      fi
      [[ ${handles["$what $arg"]} == 1 ]] || problem "$where" "$what does not handle $arg"
      ;;
    path)
      [[ -e "$what" ]] && continue
      top=${what%%/*} name=${what#*/}
      [[ "$name" == *.h && -f "$top/include/clipstream/$top/$name" ]] && continue
      [[ "$name" != */* && "$name" != *.* ]] && builds "$top" "$name" && continue
      problem "$where" "$what: no such file or folder in the repository"
      ;;
  esac
done <<<"$rows"

if ((problems)); then
  echo "check_docs: $problems problem(s) in ${docs[*]}" >&2
  exit 1
fi
echo "check_docs: the commands, options, scripts and paths of ${#docs[@]} documents are current"
