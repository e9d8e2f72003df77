"""The live view of a campaign or a run (docs/live.md): a page on localhost
that follows the folder a campaign or ``simulate`` writes — the chamber's
faces against the setpoint, each sensor's filtered X and Y, the position and
the ETA, every fault as it happens and each sensor's registry line. It reads
only the folder (``folder_state``) and answers only GET (``server``), so it
follows a campaign in another process, on the twin or on real boards, and a
finished one alike. Importing this package loads nothing: ``cli`` imports
the server only when a command serves."""
