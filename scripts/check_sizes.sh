#!/usr/bin/env bash
# Keeps the C++ sources small enough to read: lists, longest first,
#   PATH: N lines (over 800, no reason written)
#   PATH:LINE: function NAME is N lines (over 100, no reason written)
# for every source file over 800 lines and every function over 100 lines
# that has no written reason to be so long, and fails when it lists any.
#
# The sources: the *.cpp and *.h files under store/ tiler/ streamer/
# renderer/ eval/ cli/ tests/ bench/ examples/, less any folder named build*,
# third_party, third-party, thirdparty, external or vendor.
#
# A reason is a comment line of its own, with text after the colon:
# - for a function, `// Long: <reason>` on one of the 3 lines above its
#   first line (its template <...> line, if it has one);
# - for a file, `// Long file: <reason>` in its first 30 lines.
#
# A file's length is its number of lines. A function is a brace-delimited
# body opened at namespace or class level (in a namespace, extern "C" block,
# class, struct or union, or at file level) after a head with a parameter
# list: a free function, a member function defined outside or inside its
# class, a TEST / TEST_F / TEST_P / TYPED_TEST body (named SUITE.NAME), or a
# lambda assigned to a variable there (named by the variable). Its length
# runs from the first line of its head (template <...>, return type,
# signature) to its closing brace, so lambdas, local classes and everything
# else inside it count toward it. Class, struct, union and enum bodies are
# not functions; brace initializers (of variables, of members in a
# constructor's initializer list, of default arguments) are not either.
# Braces in comments, string and character literals (raw strings too) and
# preprocessor lines are not counted; each file is read once, as text, with
# no compiler, so a function whose braces differ between #if branches may
# be measured wrong.
#
# Usage: scripts/check_sizes.sh [--list] [PATH...]
#   --list  print the findings and exit 0 (for a report) instead of failing
#   PATHs   files or folders to check instead (absolute or relative to the
#           repository's root), with the same folders left out
set -euo pipefail
cd "$(dirname "$0")/.."
list=0
if [[ "${1:-}" == --list ]]; then list=1; shift; fi
if (($# == 0)); then
  for folder in util store tiler streamer renderer eval cli tests bench examples; do
    if [[ -d "$folder" ]]; then set -- "$@" "$folder"; fi
  done
fi

mapfile -t files < <(find "$@" -type d \
  \( -name 'build*' -o -name third_party -o -name third-party -o -name thirdparty \
     -o -name external -o -name vendor \) -prune -o \
  -type f \( -name '*.cpp' -o -name '*.h' \) -print | sort)
((${#files[@]})) || { echo "check_sizes: no *.cpp or *.h file in $*" >&2; exit 2; }

# One row a finding, LENGTH<tab>TEXT, and a last row #<tab>EXCUSED: how
# many files and functions over the limits have a reason written.
rows=$(awk -v max_file=800 -v max_function=100 '
  function reset_head() { head = ""; head_line = 0; head_paren = 0 }
  function start_file() {
    depth = 0; skip_depth = 0; in_comment = 0; raw_end = ""; in_directive = 0
    file_reason = 0; split("", reason); reset_head()
  }
  function end_file(lines) {
    if (depth || in_comment || raw_end != "")
      print "check_sizes: " file ": the braces, comments or raw strings do not close by its end" \
        " (#if branches?); its functions are measured as far as they do" > "/dev/stderr"
    if (lines > max_file) {
      if (file_reason) excused++
      else print lines "\t" file ": " lines " lines (over " max_file ", no reason written)"
    }
  }
  function end_function(last,    n) {
    n = last - function_line + 1
    if (n <= max_function) return
    if (reason[function_line - 1] || reason[function_line - 2] || reason[function_line - 3]) excused++
    else print n "\t" file ":" function_line ": function " function_name " is " n \
      " lines (over " max_function ", no reason written)"
  }

  # The line as code: comments and preprocessor lines dropped, each string or
  # character literal left as "" or two single quotes.
  function code_of(s,    out, c, j, delim, k) {
    out = ""
    if (raw_end != "") {
      k = index(s, raw_end)
      if (!k) return ""
      s = substr(s, k + length(raw_end)); raw_end = ""; out = "\"\""
    } else if (in_comment) {
      k = index(s, "*/")
      if (!k) return ""
      s = substr(s, k + 2); in_comment = 0
    } else if (in_directive || s ~ /^[ \t]*#/) {
      in_directive = s ~ /\\[ \t]*$/
      return ""
    }
    while (1) {
      if (!match(s, /["\x27\/]/)) return out s
      out = out substr(s, 1, RSTART - 1)
      c = substr(s, RSTART, 1); s = substr(s, RSTART + 1)
      if (c == "/") {
        if (substr(s, 1, 1) == "/") return out
        if (substr(s, 1, 1) != "*") { out = out c; continue }
        k = index(substr(s, 2), "*/")
        if (!k) { in_comment = 1; return out }
        s = substr(s, k + 3); out = out " "
        continue
      }
      if (c == "\"" && (out ~ /(^|[^A-Za-z0-9_])(u8|u|U|L)?R$/)) {  # R"delim( ... )delim"
        k = index(s, "(")
        delim = ")" substr(s, 1, k - 1) "\""; s = substr(s, k + 1)
        out = out "\"\""
        k = index(s, delim)
        if (!k) { raw_end = delim; return out }
        s = substr(s, k + length(delim))
        continue
      }
      if (c == "\x27" && out ~ /(^|[^A-Za-z0-9_.\x27])[0-9][A-Za-z0-9_.\x27]*$/) {
        out = out c; continue  # a digit separator (C++14)
      }
      for (j = 1; j <= length(s); j++) {
        k = substr(s, j, 1)
        if (k == "\\") j++
        else if (k == c) break
      }
      out = out c c; s = substr(s, j + 1)
    }
  }

  function add_to_head(t) {
    if (head_line == 0 && t ~ /[^ \t]/) head_line = FNR
    if (head_line) head = head t
  }

  # What a brace opened at namespace or class level opens, from the head
  # before it: "namespace", "class", "function" (setting function_name) or
  # "other" (an initializer, of a variable or inside the head).
  function opens(    r, op, k, pre, args, a) {
    if (head_paren > 0) return "other"
    r = head; op = ""
    if (match(r, /operator[ \t]*(\(\)|\[\]|[-+*\/%^&|~!=<>,]+)/)) {
      op = substr(r, RSTART, RLENGTH); gsub(/[ \t]/, "", op)
      r = substr(r, 1, RSTART - 1) "operator_ " substr(r, RSTART + RLENGTH)
    }
    while (gsub(/\([^()]*\)/, "`", r)) {}    # (...) -> `
    while (gsub(/<[^<>]*>/, "@", r)) {}      # <...> -> @
    gsub(/(alignas|__attribute__|__declspec|decltype)[ \t]*`/, "", r)
    if (r ~ /(^|[^A-Za-z0-9_])namespace([^A-Za-z0-9_]|$)/ || r ~ /^[ \t]*extern[ \t]*""[ \t]*$/)
      return "namespace"
    if (k = index(r, "=")) {
      pre = substr(r, 1, k - 1)
      if (substr(r, k + 1) !~ /^[ \t]*\[/ || !match(pre, /[A-Za-z_][A-Za-z0-9_]*[ \t]*$/)) return "other"
      function_name = substr(pre, RSTART, RLENGTH); sub(/[ \t]+$/, "", function_name)
      return "function"
    }
    if (match(r, /(^|[^A-Za-z0-9_])(class|struct|union|enum)([^A-Za-z0-9_]|$)/) &&
        substr(r, RSTART + RLENGTH) !~ /`/)
      return "class"
    if (!(k = index(r, "`"))) return "other"
    # A brace after a name past the parameters and a lone colon: a member of
    # a constructor initializer list, as in Foo() : a_{1} {.
    pre = r; gsub(/::/, "", pre)
    if (pre ~ /`[^:]*:/ && r ~ /[A-Za-z0-9_@][ \t]*$/) return "other"
    pre = substr(r, 1, k - 1)
    if (match(pre, /operator[ \t]+[A-Za-z_][A-Za-z0-9_:@ \t*&]*$/) ||
        match(pre, /[A-Za-z_~][A-Za-z0-9_:~@]*[ \t]*$/))
      function_name = substr(pre, RSTART, RLENGTH)
    else
      function_name = "(unnamed)"
    gsub(/@/, "", function_name); sub(/[ \t]+$/, "", function_name)
    sub(/operator_/, op, function_name)
    if (function_name ~ /^(TEST|TEST_F|TEST_P|TYPED_TEST|TYPED_TEST_P)$/ && match(head, /\([^()]*\)/)) {
      args = substr(head, RSTART + 1, RLENGTH - 2); gsub(/[ \t]/, "", args)
      if (split(args, a, ",") >= 2) function_name = a[1] "." a[2]
    }
    return "function"
  }

  # Follows the braces of one line of code.
  function follow(s,    c, what) {
    while (s != "") {
      if (skip_depth) {  # inside a function or an initializer: braces only
        if (!match(s, /[{}]/)) return
        c = substr(s, RSTART, 1); s = substr(s, RSTART + 1)
        if (c == "{") { depth++; continue }
        depth--
        if (depth >= skip_depth) continue
        skip_depth = 0
        if (skipping == "function") { end_function(FNR); reset_head() }
        else add_to_head("{}")
        continue
      }
      if (!match(s, /[{}();:]/)) { add_to_head(s); return }
      add_to_head(substr(s, 1, RSTART - 1))
      c = substr(s, RSTART, 1); s = substr(s, RSTART + 1)
      if (c == "(") { head_paren++; add_to_head(c) }
      else if (c == ")") { if (head_paren) head_paren--; add_to_head(c) }
      else if (c == ";") { if (head_paren) add_to_head(c); else reset_head() }
      else if (c == ":") {
        add_to_head(c)
        if (head ~ /^[ \t]*(public|private|protected)[ \t]*:$/) reset_head()
      } else if (c == "{") {
        what = opens()
        depth++
        if (what == "namespace" || what == "class") reset_head()
        else {
          skip_depth = depth; skipping = what
          if (what == "function") function_line = head_line ? head_line : FNR
        }
      } else if (depth > 0) {  # the end of a namespace or class
        depth--; reset_head()
      }
    }
  }

  FNR == 1 {
    if (NR > 1) end_file(lines)
    file = FILENAME; start_file()
  }
  { lines = FNR }
  /^[ \t]*\/\/[ \t]*Long:[ \t]*[^ \t]/ { reason[FNR] = 1 }
  FNR <= 30 && /^[ \t]*\/\/[ \t]*Long file:[ \t]*[^ \t]/ { file_reason = 1 }
  {
    follow(code_of($0))
    if (head_line) head = head " "
  }
  END { if (NR > 0) end_file(lines); print "#\t" excused + 0 }
' "${files[@]}")

findings=$(grep -v '^#' <<<"$rows" | sort -t $'\t' -k1,1nr -k2,2 | cut -f 2- || true)
excused=$(grep '^#' <<<"$rows" | cut -f 2)
count=0
[[ -n "$findings" ]] && count=$(wc -l <<<"$findings")
summary="${#files[@]} files, $excused over the limits with a reason written"
if ((list)); then
  [[ -n "$findings" ]] && echo "$findings"
  echo "check_sizes: $count finding(s); $summary"
elif ((count)); then
  echo "$findings" >&2
  echo "check_sizes: $count file(s) or function(s) over the limits with no reason written ($summary)" >&2
  exit 1
else
  echo "check_sizes: no file over 800 lines, no function over 100 lines without a reason written ($summary)"
fi
