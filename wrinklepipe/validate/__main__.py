"""``python -m wrinklepipe.validate [docs/ISSUES.md]``: write the issue-code table."""

from wrinklepipe.validate.issues_table import main

raise SystemExit(main())
