#!/bin/sh
# Remakes the recording screenshots of the README and docs/recordings.md (docs/img/recording-*.png) in the real viewer, headless:
# each recording is opened in `rerun --headless` and, once the viewer's start-up notices have
# faded, a screenshot is asked for through the viewer's gRPC client (it shows the last step).
# Needs: a release build, `pip install rerun-sdk==0.36.3` (viewer and client, with Pillow) and,
# without a GPU, `apt-get install -y mesa-vulkan-drivers`. Run from the repository's root;
# `docs/screenshots.sh dam-2d method-flip` remakes only the shots named.
set -eu
only="$*"
bin=target/release/cellflip
tmp=$(mktemp -d)
shoot() { # name, then a cellflip command (run or compare) and its arguments
    name=$1
    shift
    case " ${only:-$name} " in *" $name "*) ;; *) return 0 ;; esac
    "$bin" "$@" -q --save "$tmp/$name.rrd"
    # In its own process group: `rerun` may be a wrapper that starts the viewer as a child.
    setsid rerun "$tmp/$name.rrd" --headless --window-size 1600x900 >"$tmp/$name.log" 2>&1 &
    viewer=$!
    python3 - "$tmp/$name.png" <<'EOF'
import sys, time
from rerun.experimental import ViewerClient
time.sleep(4)
client = ViewerClient()
time.sleep(14)
client.save_screenshot(sys.argv[1])
EOF
    kill -- "-$viewer"
    sleep 2
    # A palette of 192 colours keeps each image near 150 KB.
    python3 -c "from PIL import Image; import sys; Image.open(sys.argv[1]).convert('RGB').quantize(192).save(sys.argv[2], optimize=True)" \
        "$tmp/$name.png" "docs/img/recording-$name.png"
}
shoot dam-2d run dam-2d --steps 60
shoot band-2d run dam-2d --band paths --res 40 --steps 60
shoot obstacle-2d run falling-obstacle-2d --steps 80
shoot dam-3d run dam-3d --steps 40
shoot compare-2d compare dam-2d --duration 1.2
shoot compare-3d compare dam-3d --res 32 --methods flip,idp,ccp --duration 0.8
# The method pages' pictures (docs/methods/; ccp's is band-2d, nbflip's a plot).
shoot method-flip run dam-2d --method flip --steps 60
shoot method-idp run dam-2d --method idp --steps 60
shoot method-powerpic run dam-2d --method powerpic --steps 60
rm -r "$tmp"
ls -l docs/img/recording-*.png
