#!/bin/sh
# ctest python_install: the install command of docs/python.md into a fresh virtual environment, then `import hgs`
# from there (outside the source and build folders). Usage: install_test.sh PYTHON BUILD_DIR VENV_DIR [CMAKE]
set -eu
python="$1" build="$2" venv="$3" cmake="${4:-cmake}"
rm -rf "$venv"
"$python" -m venv --without-pip --system-site-packages "$venv"
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("platlib"))')"
"$cmake" --install "$build" --component python --prefix "$site" >/dev/null
cd /
"$venv/bin/python" -c 'import hgs, sys; assert hgs.__file__.startswith(sys.prefix), hgs.__file__; print(hgs.__file__)'
