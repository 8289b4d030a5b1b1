#!/usr/bin/env bash
# Writes what is made from the programs' --help: the man pages (help2man) of plenopiv (plenopiv(1),
# and one page per command in git's style: plenopiv-process(1), plenopiv-run-start(1), ...) and of
# plenopivd (plenopivd(8)), gzipped into OUT/man1 and OUT/man8, and plenopiv's bash completion
# (OUT/bash-completion/plenopiv: every command's subcommands and options as tables, so that a Tab
# costs no call of plenopiv). Each --help is asked once, kept in OUT/help.
# Usage: make-docs.sh PLENOPIV PLENOPIVD VERSION CONFIG_DIR OUT
#   CONFIG_DIR: where plenopivd.yaml is installed (/etc/plenopiv), which plenopivd(8) names.
set -euo pipefail
plenopiv=$1
plenopivd=$2
version=$3
config_dir=$4
out=$5

help_dir=$out/help
rm -rf "$help_dir" "$out/man1" "$out/man8" "$out/bash-completion"
mkdir -p "$help_dir" "$out/man1" "$out/man8" "$out/bash-completion"

# The first word of each line of a --help's "Subcommands:" list.
subcommands() {
  awk '/^Subcommands:/ { listed = 1; next } listed && /^$/ { exit } listed && /^  [a-z]/ { print $1 }' "$1"
}
# The options of a --help's "Options:" list, each by its long name (its short one when it has
# none); with "value", only those that take one (a type follows: TEXT, INT=0, TEXT:FILE; not a
# note such as "Excludes: --json").
options() {
  awk -v value="${2:-}" '/^Options:/ { listed = 1; next } listed && /^$/ { exit }
    listed && /^  -/ {
      n = split($1, names, ","); name = names[1]
      for (i = 1; i <= n; ++i) if (names[i] ~ /^--/) { name = names[i]; break }
      if (value == "" || $2 ~ /^[A-Z][A-Z_]*([:=]|$)/) print name
    }' "$1"
}
words() { tr '\n' ' ' | sed 's/ $//'; }

# The command tree, depth first: paths ("", "run", "run start", ...), each --help in
# help/plenopiv[-<path words>].txt.
paths=()
walk() {
  local file sub
  file=$help_dir/$(IFS=-; echo "plenopiv${*:+-$*}").txt
  "$plenopiv" "$@" --help > "$file"
  paths+=("$*")
  for sub in $(subcommands "$file"); do
    walk "$@" "$sub"
  done
}
walk
"$plenopivd" --help > "$help_dir/plenopivd.txt"
help_file() { echo "$help_dir/$(IFS=-; echo "plenopiv${*:+-$*}").txt"; }

# help2man reads the kept texts through this stand-in for plenopiv: `show run start --help`.
cat > "$help_dir/show" <<'SHOW'
#!/usr/bin/env bash
# Prints the kept --help of the command given before --help.
args=("${@:1:$#-1}")
cat "$(dirname "$0")/$(IFS=-; echo "plenopiv${args[*]:+-${args[*]}}").txt"
SHOW
chmod +x "$help_dir/show"

# page FILE HELP2MAN-ARGS...: one gzipped page (no time stamp in the gzip header: reproducible).
page() {
  local file=$1
  shift
  help2man --no-info --source="plenopiv $version" "$@" | gzip -9n > "$file.tmp"
  mv "$file.tmp" "$file"
}

see_also=""
for path in "${paths[@]:1}"; do
  read -ra path_words <<<"$path"
  name=plenopiv-$(IFS=-; echo "${path_words[*]}")
  description=$(head -1 "$(help_file "${path_words[@]}")")
  page "$out/man1/$name.1.gz" --section=1 --name="$description" --version-string="$name $version" \
    --help-option="$path --help" "$help_dir/show"
  see_also+=".TP"$'\n'"\\fB$name\\fR(1)"$'\n'"$description"$'\n'
done
include=$help_dir/include
printf '[SEE ALSO]\n%s.TP\n\\fBplenopivd\\fR(8)\nthe daemon\n' "$see_also" > "$include"
page "$out/man1/plenopiv.1.gz" --section=1 --name="$(head -1 "$(help_file)" | sed 's/^plenopiv: //')" \
  --version-string="plenopiv $version" --help-option=--help --include="$include" "$help_dir/show"

printf '[FILES]\n%s\n[SEE ALSO]\n%s\n' \
  "$config_dir/plenopivd.yaml: the configuration the unit plenopivd.service starts it with." \
  "plenopiv(1), plenopiv-status(1), systemctl(1)" > "$include"
page "$out/man8/plenopivd.8.gz" --section=8 --name="$(head -1 "$help_dir/plenopivd.txt" | sed 's/^plenopivd: //')" \
  --version-string="plenopivd $version" --include="$include" "$plenopivd"

# The completion: three tables by command path, then the function that reads them.
table() {
  local function=$1 kind=$2 path
  echo "$function()"
  echo "{"
  echo "    case \$1 in"
  for path in "${paths[@]}"; do
    read -ra path_words <<<"$path"
    case $kind in
      commands) echo "        \"$path\") echo '$(subcommands "$(help_file "${path_words[@]}")" | words)' ;;" ;;
      options) echo "        \"$path\") echo '$(options "$(help_file "${path_words[@]}")" | words)' ;;" ;;
      values) echo "        \"$path\") echo '$(options "$(help_file "${path_words[@]}")" value | words)' ;;" ;;
    esac
  done
  echo "    esac"
  echo "}"
}
{
  cat <<'HEAD'
# bash completion for plenopiv: its commands and their options. Generated from plenopiv's --help by
# packaging/make-docs.sh; installed as share/bash-completion/completions/plenopiv (needs the
# bash-completion package).

# A command's subcommands, options and options that take a value, by its path ("run start").
HEAD
  table _plenopiv_commands commands
  table _plenopiv_options options
  table _plenopiv_value_options values
  cat <<'BODY'

_plenopiv()
{
    local cur prev words cword
    _init_completion || return

    # The command path typed so far: each word that names a subcommand of the path before it.
    local path="" i
    for ((i = 1; i < cword; i++)); do
        if [[ " $(_plenopiv_commands "$path") " == *" ${words[i]} "* ]]; then
            path=${path:+$path }${words[i]}
        fi
    done

    # The value of an option: mostly a file (camera file, frames, configs, outputs).
    if [[ $prev == -* && " $(_plenopiv_value_options "$path") $(_plenopiv_value_options "") " == *" $prev "* ]]; then
        _filedir
        return
    fi
    if [[ $cur == -* ]]; then
        # The command's own options and the global ones, which may follow the command too.
        COMPREPLY=($(compgen -W "$(_plenopiv_options "$path") $(_plenopiv_options "")" -- "$cur"))
        return
    fi
    local commands
    commands=$(_plenopiv_commands "$path")
    if [[ -n $commands ]]; then
        COMPREPLY=($(compgen -W "$commands" -- "$cur"))
        return
    fi
    _filedir
} &&
    complete -F _plenopiv plenopiv
BODY
} > "$out/bash-completion/plenopiv.tmp"
mv "$out/bash-completion/plenopiv.tmp" "$out/bash-completion/plenopiv"
