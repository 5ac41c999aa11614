from awda_bench.cli import main

raise SystemExit(main())
