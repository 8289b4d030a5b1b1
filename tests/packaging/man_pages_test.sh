#!/usr/bin/env bash
# The man pages the build made (packaging/make-docs.sh) render without groff warnings, plenopiv(1)
# names every command `plenopiv --help` lists and each has its own page with its options, and
# plenopivd(8) shows --config. Usage: man_pages_test.sh BUILD_DIR
set -euo pipefail
build=$1
plenopiv=$build/bin/plenopiv
man_dir=$build/packaging
failures=0
fail() {
  echo "FAIL: $*" >&2
  failures=$((failures + 1))
}

# render PAGE: the page as text; groff's warnings (bad requests, escapes) fail the test.
render() {
  local warnings
  warnings=$(MANWIDTH=100 man --warnings -l "$1" 2>&1 >/dev/null)
  [ -z "$warnings" ] || fail "$1: groff warns: $warnings"
  MANWIDTH=100 man -l "$1" 2>/dev/null | col -b
}

commands=$("$plenopiv" --help | awk '/^Subcommands:/ { listed = 1; next } listed && /^$/ { exit }
                                     listed && /^  [a-z]/ { print $1 }')
[ "$(echo "$commands" | wc -w)" -ge 10 ] || fail "plenopiv --help lists only: $commands"

main_page=$(render "$man_dir/man1/plenopiv.1.gz")
grep -q '^NAME' <<<"$main_page" || fail "plenopiv(1) has no NAME section"
for command in $commands; do
  grep -qE "^ +$command( |$)" <<<"$main_page" || fail "plenopiv(1) does not list the command $command"
  grep -q "plenopiv-$command(1)" <<<"$main_page" || fail "plenopiv(1)'s SEE ALSO lacks plenopiv-$command(1)"
  [ -f "$man_dir/man1/plenopiv-$command.1.gz" ] || fail "no page plenopiv-$command.1.gz"
done

# A nested command's page: its synopsis and an option of its own.
run_start=$(render "$man_dir/man1/plenopiv-run-start.1.gz")
grep -q 'plenopiv run start \[OPTIONS\]' <<<"$run_start" || fail "plenopiv-run-start(1) lacks its synopsis"
grep -q -- '-c,--config' <<<"$run_start" || fail "plenopiv-run-start(1) lacks -c,--config"
process=$(render "$man_dir/man1/plenopiv-process.1.gz")
grep -q -- '--threads' <<<"$process" || fail "plenopiv-process(1) lacks --threads"

daemon_page=$(render "$man_dir/man8/plenopivd.8.gz")
grep -q 'PLENOPIVD(8)' <<<"$daemon_page" || fail "plenopivd(8) has no section-8 header"
grep -q -- '-c,--config' <<<"$daemon_page" || fail "plenopivd(8) lacks -c,--config"
grep -q 'plenopivd.yaml' <<<"$daemon_page" || fail "plenopivd(8) does not name its config file"

[ "$failures" -eq 0 ] || { echo "$failures failure(s)" >&2; exit 1; }
echo "man pages: $(ls "$man_dir"/man1 | wc -l) in section 1, plenopivd(8); $(echo $commands | wc -w) commands named"
