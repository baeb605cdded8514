# Sourced by the street-stream bench scripts (paired_speed.sh, cache_misses.sh): the stream
# ($IMR_SHARED_DIR/data/street-stream, default ../shared beside the checkout) and the job they
# run on it, every view a keyframe. Sets STREAM and WORK (a fresh folder named after $1), or
# exits 2 when the stream is absent.
#   street_setup SCRIPT_NAME
#   street_job NAME THREADS   writes $WORK/NAME/job.json, its output in $WORK/NAME/out
street_setup() {
  local root
  root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)
  STREAM=${IMR_SHARED_DIR:-$root/../shared}/data/street-stream/slam.json
  if [ ! -f "$STREAM" ]; then
    echo "$1: $STREAM not found (set IMR_SHARED_DIR); nothing measured" >&2
    exit 2
  fi
  WORK=$(mktemp -d "/tmp/imr-$1-XXXXXX")
}
street_job() {
  mkdir -p "$WORK/$1"
  cat > "$WORK/$1/job.json" <<J
{"sequences":["$STREAM"],"input":{"format":"slam_json","options":{"views_per_keyframe":1}},
 "engine":{"threads":$2},"pipeline":[{"kind":"exporter","plugin":"org.imr.exporter.assimp"}],
 "output":{"directory":"$WORK/$1/out","formats":["ply"]}}
J
}
