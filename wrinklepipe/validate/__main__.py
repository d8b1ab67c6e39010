"""``python -m wrinklepipe.validate [docs/ISSUES.md]``: write the issue-code table."""

from wrinklepipe.validate.catalogue import main

raise SystemExit(main())
