#!/usr/bin/env bash
# Set vrecho up on a fresh Debian machine: system libraries, PyTorch's CPU build, the package.
#   ./install.sh          everything needed to run vrecho
#   ./install.sh --test   and what the tests need (pytest, fast-bss-eval, JACK-Client; Debian's chromium
#                         and jackd2: the walkthrough in a real browser, vrecho watch on a real audio server)
set -euo pipefail
cd "$(dirname "$0")"
extras=""
[ "${1:-}" = "--test" ] && extras="[test]"
sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
if command -v apt-get >/dev/null; then
  # open3d's wheels need these (NOTES.md); soundfile needs libsndfile, vrecho watch PortAudio. The
  # tests open the demo's walkthrough in a real headless Chromium (vrecho demo also screenshots it
  # when one is there) and run vrecho watch against a JACK server (its dummy backend: no sound card).
  for_tests=""; [ -n "$extras" ] && for_tests="chromium jackd2"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends \
    libusb-1.0-0 libgl1 libegl1 libx11-6 libudev1 libgomp1 libsndfile1 libportaudio2 $for_tests >/dev/null
fi
# torch first and pinned exactly: it takes the CPU build that lies on these machines; a loose
# requirement would pull the registry's newest CUDA build (several GB).
python3 -m pip install -q --disable-pip-version-check torch==2.13.0
python3 -m pip install -q --disable-pip-version-check -e ".${extras}"
if command -v pyenv >/dev/null; then pyenv rehash; fi
# The headset call's compiled kernels, made once here (some 10 s) and cached: never in an audio callback.
python3 -c "from vrecho.headset import BoundaryMonitor; BoundaryMonitor()"  # (its kernels and faint.py's)
echo "vrecho installed: $(command -v vrecho || echo 'python3 -m vrecho')"
