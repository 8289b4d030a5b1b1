#!/usr/bin/env bash
# The bash completion the build made (packaging/make-docs.sh) in a real bash with bash-completion
# loaded: `complete -p` names it, and it completes commands, nested commands, a command's options,
# the global options after a command, and a file after an option that takes a value.
# Usage: bash_completion_test.sh BUILD_DIR
set -uo pipefail
build=$1
completion=$build/packaging/bash-completion/plenopiv
[ -f /usr/share/bash-completion/bash_completion ] ||
  { echo "FAIL: bash-completion is not installed (Debian package bash-completion; scripts/setup.sh)" >&2; exit 1; }
exec bash --norc --noprofile -c '
source /usr/share/bash-completion/bash_completion
source "$1"
cd "$(mktemp -d)"
touch camera-small.yaml
failures=0
complete -p plenopiv | grep -q -- "-F _plenopiv plenopiv" || { echo "FAIL: complete -p: $(complete -p plenopiv 2>&1)"; exit 1; }

# expect WORDS... -- CANDIDATES...: completing the last word gives exactly these candidates.
expect() {
  local -a words=() want=()
  while [ "$1" != -- ]; do words+=("$1"); shift; done
  shift
  want=("$@")
  COMP_WORDS=("${words[@]}")
  COMP_CWORD=$((${#words[@]} - 1))
  COMP_LINE="${words[*]}"
  COMP_POINT=${#COMP_LINE}
  COMPREPLY=()
  _plenopiv plenopiv "${words[-1]}" "${words[-2]}"
  local got
  got=$(printf "%s\n" "${COMPREPLY[@]}" | sort | xargs)
  if [ "$got" != "$(printf "%s\n" "${want[@]}" | sort | xargs)" ]; then
    echo "FAIL: [${words[*]}] completes to [$got], expected [${want[*]}]"
    failures=$((failures + 1))
  fi
}
expect plenopiv proc -- process
expect plenopiv run st -- start stop
expect plenopiv simulate pa -- particles pair
expect plenopiv run start --con -- --config
expect plenopiv process --thr -- --threads
expect plenopiv status --j -- --json
expect plenopiv status --time -- --timeout
expect plenopiv --timeout 5 dev -- devices
expect plenopiv camera --camera camera-s -- camera-small.yaml
[ "$failures" -eq 0 ] || exit 1
echo "bash completion: commands, nested commands and options complete"
' bash "$completion"
