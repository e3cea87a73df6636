# Sourced by the training scripts (scripts/train-*): one wall-time budget shared by the
# train.py runs of a multi-stage recipe, so that a session can stop it and a later one resume.
#
#   budget_start NAME MINUTES   MINUTES 0: no budget. NAME prefixes the messages.
#   b=$(budget)                 before each stage: "--session-minutes LEFT" for train.py, nothing
#                               without a budget; exit status 3 once it is spent (as an
#                               assignment under set -e, that ends the script).

budget_start() {
  budget_name=$1
  budget_minutes=$2
  [[ $budget_minutes =~ ^[0-9]+([.][0-9]+)?$ ]] || {
    echo "$budget_name: --session-minutes takes minutes as a number, got '$budget_minutes'" >&2; exit 2; }
  budget_deadline=$(awk -v now="$(date +%s)" -v m="$budget_minutes" 'BEGIN { printf "%d", now + m * 60 }')
}

budget() {
  [ "$budget_minutes" = 0 ] && return 0
  local left
  left=$(awk -v now="$(date +%s)" -v d="$budget_deadline" 'BEGIN { printf "%.2f", (d - now) / 60 }')
  if awk -v l="$left" 'BEGIN { exit !(l <= 0) }'; then
    echo "$budget_name: the session budget of $budget_minutes min is spent; give the same command again to continue" >&2
    exit 3
  fi
  echo "--session-minutes $left"
}
