# shellcheck shell=bash
# Sourced by start-cluster, stop-cluster and test: where the single-node Slurm cluster of CI lives.
# Everything (configuration, munge key and socket, state, spool, logs, pid files) is under one
# directory, so nothing in /etc is touched and stop-cluster knows what to stop.
: "${OPTIMIS_SLURM_DIR:=/tmp/optimis-slurm}"
: "${OPTIMIS_SLURMCTLD_PORT:=6817}"
: "${OPTIMIS_SLURMD_PORT:=6818}"
export OPTIMIS_SLURM_DIR OPTIMIS_SLURMCTLD_PORT OPTIMIS_SLURMD_PORT
# Every Slurm command (sinfo, sbatch, squeue, scontrol) and daemon reads this configuration.
export SLURM_CONF="$OPTIMIS_SLURM_DIR/etc/slurm.conf"
export MUNGE_SOCKET="$OPTIMIS_SLURM_DIR/munge/munge.socket.2"

# The n-th ```sh block after the line that starts with $1 in README.md (run from the repository's
# root): how the Slurm tests take the README's commands as they stand.
readme_block() {
    awk -v marker="$1" -v want="$2" '
        index($0, marker) == 1 { found = 1; next }
        found && /^```sh$/ { n++; inside = 1; next }
        inside && /^```$/ { inside = 0; if (n == want) exit; next }
        inside && n == want { print }
    ' README.md
}
