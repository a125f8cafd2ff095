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
