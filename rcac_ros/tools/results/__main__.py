import sys

from rcac_ros.tools.results.page import main

sys.exit(main())
