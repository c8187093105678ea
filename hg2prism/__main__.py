from hg2prism.cli import main

raise SystemExit(main())
