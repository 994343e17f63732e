#!/usr/bin/env bash
# Print the path of a working Python 3.12+ interpreter, or fail with a message saying what to install.
set -u
for cand in python3.12 python3.13 python3; do
  if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; then
    command -v "$cand"; exit 0
  fi
done
# pyenv installs interpreters that its shims hide unless selected
for cand in "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.1[2-9]*/bin/python3; do
  if [ -x "$cand" ] && "$cand" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; then
    echo "$cand"; exit 0
  fi
done
echo "error: drake-abs needs Python >= 3.12 (Drake ships wheels for 3.12+ only); install python3.12" >&2
exit 1
