from wrinklepipe.cli import main

raise SystemExit(main())
