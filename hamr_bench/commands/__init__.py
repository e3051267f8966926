"""One module per `hamr-bench` sub-command. Each module exposes `register(subparsers)`, which adds its parser and
sets `func` to a handler taking the parsed arguments and returning an exit code. Registration must stay cheap:
heavy imports (numpy stacks, drivers, analysis) happen inside the handler."""
