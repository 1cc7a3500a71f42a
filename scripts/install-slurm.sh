#!/usr/bin/env bash
# Installs Slurm's daemons and commands and MUNGE (Debian's slurm-wlm and munge) for the
# test that runs a one-node Slurm cluster on this machine (tests/tests/slurm.rs): it starts
# munged, slurmctld and slurmd itself, with a configuration of its own in a temporary
# folder, and stops them. Nothing is started or enabled here.
# Exits 0 when they are there afterwards, 1 (saying why) when they could not be installed.
set -euo pipefail

have_slurm() {
    for program in munged slurmctld slurmd sbatch squeue scancel sinfo; do
        command -v "$program" >/dev/null || [ -x "/usr/sbin/$program" ] || return 1
    done
}

if have_slurm; then
    echo "install-slurm: Slurm and MUNGE are installed"
    exit 0
fi
# Whether or not the packages start their own services, the test's daemons use ports, a
# MUNGE socket and a key of their own.
bash "$(dirname "$0")/apt-install.sh" install-slurm slurm-wlm munge
have_slurm || { echo "install-slurm: slurm-wlm installed but its programs are not found" >&2; exit 1; }
echo "install-slurm: Slurm and MUNGE are installed"
