#!/usr/bin/env bash
# Checks that every section citation in the sources names a section of docs/METHOD.md.
#
# Citations are "METHOD <n>" / "METHOD <n>.<m>" anywhere in lib/ apps/ tests/ bench/ scripts/
# fuzz/ configs/ data_splits/ docs/ README.md ARCHITECTURE.md (this script excepted); "SPEC <n>",
# which names no document of the repository, is refused too. Sections are the '#' headings of docs/METHOD.md whose text starts with a number
# ("## 3. Network" is section 3, "### 3.2 TransHE" section 3.2; fenced code blocks are skipped).
# Prints one summary line and exits 0 when every citation resolves; otherwise lists each
# dangling citation as "file:line: SPEC 3.7" on stderr and exits 1.
#
# Usage: scripts/check-citations.sh [REPOSITORY_ROOT]   (default: this script's parent folder)
set -euo pipefail

root="${1:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}"
if [[ ! -d "$root" ]]; then
  echo "check-citations: error: '$root' is not a folder" >&2
  exit 1
fi
cd "$root"
method="docs/METHOD.md"
if [[ ! -f "$method" ]]; then
  echo "check-citations: error: '$root/$method' does not exist" >&2
  exit 1
fi
self="scripts/check-citations.sh"

# Section numbers of the document's headings, one per line.
sections="$(awk '
  /^[[:space:]]*(```|~~~)/ { fence = !fence; next }
  fence { next }
  /^#+[[:space:]]+[0-9]/ {
    sub(/^#+[[:space:]]+/, "")
    if (match($0, /^[0-9]+(\.[0-9]+)*/)) print substr($0, RSTART, RLENGTH)
  }' "$method" | sort -u)"
if [[ -z "$sections" ]]; then
  echo "check-citations: error: $method has no numbered headings" >&2
  exit 1
fi

# Citations as "file:line:SPEC 3.2", from the places that exist in this tree.
targets=()
for t in lib apps tests bench scripts fuzz configs data_splits docs README.md ARCHITECTURE.md; do
  [[ -e "$t" ]] && targets+=("$t")
done
citations=""
if ((${#targets[@]} > 0)); then
  citations="$(grep -rInoE '\b(SPEC|METHOD) [0-9]+(\.[0-9]+)?' -- "${targets[@]}" \
    | grep -v "^${self}:" || true)"
fi

total=0
bad=()
declare -A cited=()
declare -A known=()
while IFS= read -r s; do known["$s"]=1; done <<<"$sections"
if [[ -n "$citations" ]]; then
  while IFS= read -r entry; do
    file="${entry%%:*}"
    rest="${entry#*:}"
    line="${rest%%:*}"
    cite="${rest#*:}"
    number="${cite#* }"
    total=$((total + 1))
    cited["$number"]=1
    if [[ $cite == SPEC* ]]; then
      bad+=("$file:$line: $cite (cite the repository's own document: METHOD $number)")
    elif [[ -z "${known[$number]:-}" ]]; then
      bad+=("$file:$line: $cite")
    fi
  done <<<"$citations"
fi

if ((${#bad[@]} > 0)); then
  printf '%s\n' "${bad[@]}" >&2
  echo "check-citations: ${#bad[@]} of $total citations name no section of $method" >&2
  exit 1
fi
echo "check-citations: $total citations of ${#cited[@]} sections, all resolve"
