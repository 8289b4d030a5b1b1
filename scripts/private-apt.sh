# Sourced by scripts that fetch Debian packages or sources without touching the machine's apt: an
# apt of its own in a folder (its sources, lists and cache), signed by Debian's archive keyring.
#   private_apt DIR TYPE SUITE   e.g. private_apt build-x/apt deb-src bookworm
# writes DIR/sources.list (TYPE: deb or deb-src; SUITE of http://deb.debian.org/debian, main), sets
# the array apt_options for `apt-get "${apt_options[@]}" ...` and updates the lists.
private_apt() {
  local dir=$1 type=$2 suite=$3
  mkdir -p "$dir/lists/partial" "$dir/cache/archives/partial"
  echo "$type [signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] http://deb.debian.org/debian $suite main" \
    > "$dir/sources.list"
  apt_options=(-o Dir::Etc::SourceList="$dir/sources.list" -o Dir::Etc::SourceParts=/dev/null
    -o Dir::State::Lists="$dir/lists" -o Dir::Cache="$dir/cache" -o APT::Sandbox::User=root)
  apt-get "${apt_options[@]}" update -qq
}
