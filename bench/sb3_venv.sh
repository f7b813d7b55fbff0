# Sourced by the side-by-side benchmarks: sets `venv` to a virtual environment with torch, Gymnasium and
# Stable-Baselines3: VENV if given (it must have them), else the checkout's .venv if it has them, else bench/.venv,
# installed there on the first run (CPU-only torch).
has_sb3() { [ -x "$1/bin/python" ] && "$1/bin/python" -c "import torch, gymnasium, stable_baselines3" 2>/dev/null; }
if [ -n "${VENV:-}" ]; then
  venv="$VENV"
  has_sb3 "$venv" || { echo "VENV=$venv: no python there with torch, gymnasium and stable_baselines3" >&2; exit 1; }
elif has_sb3 .venv; then
  venv=.venv
else
  venv=bench/.venv
fi
if ! has_sb3 "$venv"; then
  echo "== installing Stable-Baselines3 into $venv (CPU-only torch)"
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --upgrade pip
  # PyTorch's CPU-only wheel (~200 MB); PyPI's Linux wheel needs the CUDA libraries (several GB) even to import.
  "$venv/bin/pip" install --quiet torch --index-url https://download.pytorch.org/whl/cpu ||
    "$venv/bin/pip" install --quiet torch
  "$venv/bin/pip" install --quiet stable-baselines3 gymnasium
fi

