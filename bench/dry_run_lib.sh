# What the dry runs of the GPU scripts share (gpu_check_dry_run.sh, perf_gpu_dry_run.sh), sourced
# from the repository root: exit 77 (a skip for CTest) where a GPU is visible; a temporary folder
# TMP removed at exit; expect DESCRIPTION COMMAND..., which counts a problem when COMMAND fails.
if nvidia-smi -L > /dev/null 2>&1; then
  echo "a GPU is visible: run the staged script itself"
  exit 77
fi
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
problems=0
expect() {
  local what=$1
  shift
  if "$@"; then echo "ok: $what"; else echo "PROBLEM: $what" >&2; problems=$((problems + 1)); fi
}
