#!/usr/bin/env bash
# Here, before carrying the working tree to a lent GPU machine: write .gpu/b/source_env.sh, which sets IRMCL_GIT_SHA
# to this checkout's commit ("-dirty" when tracked files differ from it). The GPU machine's copy has the tree but a
# stale history, so without it every run there records the wrong commit in its manifest (irmcl_warp/runs.py
# _git_sha). There: source .gpu/b/remote_env.sh && source .gpu/b/source_env.sh && <command>
set -euo pipefail
sha=$(git rev-parse HEAD)
[ -n "$(git status --porcelain --untracked-files=no)" ] && sha="$sha-dirty"
mkdir -p .gpu/b
echo "export IRMCL_GIT_SHA=$sha" > .gpu/b/source_env.sh
echo "IRMCL_GIT_SHA=$sha -> .gpu/b/source_env.sh"
